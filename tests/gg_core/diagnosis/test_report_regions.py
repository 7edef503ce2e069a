from gg_core.diagnosis.report_regions import candidate_regions


def test_each_region_candidate_names_its_own_region_and_the_others_none():
    """A scanned candidate keeps its scan's region, None where no patch explained enough; a candidate that chose
    between the maps' extents keeps the chosen one; candidates neither scanned nor chose are not named (they act
    on the maps' region)."""
    loc = {"region_vertices": [0, 1],
           "scanned_regions": {"rest_length_region": {"region_vertices": [3, 4]},
                               "heavy_region": {"region_vertices": None}},
           "region_choices": {"region_stiffness": {"chosen": "grown", "region_vertices": [0, 1, 2]}}}
    assert candidate_regions(loc) == {"rest_length_region": [3, 4], "heavy_region": None,
                                      "region_stiffness": [0, 1, 2]}
    assert candidate_regions({"region_vertices": [0, 1]}) == {}
