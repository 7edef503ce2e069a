"""Cross-validation over sequences: each recording held out once, so a confirmation does not hang on whichever
sequence happened to be held out.

The diagnosis first refits every proposed candidate on the training sequences and judges it on the held-out ones
(fold 0, the split the user gave). A single held-out recording can hide an effect it barely exercises: a skirt's
arm swing hardly moves the skirt, so hidden air damping, which our simulator's captures show clearly on the walk
and the torso twist (training-rollout gains of 30-41 %, session 23), gained only 2-8 % on it and was not
confirmed. The candidates fold 0 found worth it (`finalists`) are therefore refitted again in the other folds:
each training sequence is held out in turn, and everything of that fold (baseline, residual, regression start,
refit) is fitted without it. A candidate is confirmed on the folds' mean held-out gain, and must help the
held-out rollouts in most folds and the training rollouts in every fold (CrossValidation.confirmed).

What the extra folds do not redo: the choice of finalists and of a localized region candidate's region (both from
fold 0's training sequences, which include the sequence a later fold holds out; a spurious choice fitted to that
sequence's quirks gains nothing there, because the fold's refit no longer sees it), the rest state and the attached
vertices (properties of the garment, which every rollout starts from anyway). A region chosen on training rollouts
(scan.py) is chosen again on each fold's own: fold 0's rollouts include the recording the fold holds out.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .confirm import Trial


@dataclass
class Fold:
    """One split: the sequences fitted on and held out, what trials are judged against (verdict.judge_reference),
    the candidates' trials and, for benchmarks, the trials of the candidates given the truth (`given`: the true
    effect, on its true region), which are never named."""

    train: list[str]
    heldout: list[str]
    reference: Trial
    trials: dict[str, Trial]
    given: dict[str, Trial] = field(default_factory=dict)

    def gains(self, name: str) -> tuple[float, float, float]:
        """(held-out gain, training-rollout gain, held-out improvement in m) of the candidate's trial."""
        return self._gains(self.trials[name])

    def given_gain(self, name: str) -> float:
        """Held-out gain of the trial given the truth `name`."""
        return self._gains(self.given[name])[0]

    def _gains(self, t: Trial) -> tuple[float, float, float]:
        ref = self.reference
        return (1.0 - t.heldout_l2 / ref.heldout_l2, 1.0 - t.train_l2 / ref.train_l2, ref.heldout_l2 - t.heldout_l2)

    def to_json(self) -> dict:
        def entry(t: Trial) -> dict:
            held, train, _ = self._gains(t)
            return {"heldout_l2": t.heldout_l2, "train_rollout_l2": t.train_l2, "heldout_gain": held,
                    "train_rollout_gain": train, "refit": t.values, "form": t.form or None}

        return {"train": self.train, "heldout": self.heldout, "heldout_l2_before": self.reference.heldout_l2,
                "train_rollout_l2_before": self.reference.train_l2,
                "trials": {n: entry(t) for n, t in self.trials.items()},
                "given_truth": {n: entry(t) for n, t in self.given.items()}}


def extra_splits(train: list[str], heldout: list[str]) -> list[tuple[list[str], list[str]]]:
    """The folds after the given split: each training sequence held out in turn, fitted on all the others."""
    names = train + heldout
    return [([n for n in names if n != s], [s]) for s in train]


def finalists(fold: Fold, min_gain: float, count: int) -> list[str]:
    """At most `count` of the fold's candidates worth the other folds: those whose refit gained at least
    `min_gain` on the held-out or on the training rollouts, by the larger of those gains."""
    def larger(n: str) -> float:
        held, train, _ = fold.gains(n)
        return max(held, train)

    return sorted((n for n in fold.trials if larger(n) >= min_gain), key=lambda n: -larger(n))[:count]


@dataclass
class CrossValidation:
    """The folds, the user's split first; a candidate's figures are over the folds that trialled it."""

    folds: list[Fold]

    def per_fold(self, name: str) -> np.ndarray:
        """[F,3] Fold.gains of `name` in every fold that trialled it."""
        return np.array([f.gains(name) for f in self.folds if name in f.trials])

    def count(self, name: str) -> int:
        """How many folds trialled `name`."""
        return sum(name in f.trials for f in self.folds)

    def complete(self, name: str) -> bool:
        return self.count(name) == len(self.folds)

    def mean_gains(self, name: str) -> tuple[float, float]:
        """(mean held-out gain, mean training-rollout gain) over the folds."""
        g = self.per_fold(name)
        return float(g[:, 0].mean()), float(g[:, 1].mean())

    def refit_ranges(self, name: str) -> dict[str, list]:
        """[smallest, largest] over the folds of each refitted term or region value of `name` (per component for
        vectors): how closely the recordings determine it. Measured (session 24, our simulator's hidden air
        damping, seed 2): alpha 7.9 / 12.7 / 12.0 /s without the arm swing / walk / twist, the truth 10."""
        values = [f.trials[name].values for f in self.folds if name in f.trials]
        keys = dict.fromkeys(k for vals in values for k in vals if not k.startswith("material."))
        out = {}
        for key in keys:    # a fold refits only some components of some candidates (anisotropy: the positive ones)
            v = np.array([vals[key] for vals in values if key in vals], np.float64)
            out[key] = [v.min(0).tolist(), v.max(0).tolist()]
        return out

    def confirmed(self, name: str, min_gain: float, min_gain_mm: float) -> bool:
        """Trialled in every fold; the mean held-out gain at least `min_gain` and the mean improvement at least
        `min_gain_mm`; the held-out rollouts better in most folds (every fold, by half of `min_gain`, with fewer
        than three) and the training rollouts in every fold.

        Why most and not every held-out fold: a recording that barely exercises the effect does not show it.
        Measured (session 24, our simulator's hidden air damping, seed 2): mass damping gained -2 / +28 / +42 %
        held out on the arm swing / walk / torso twist, where the true effect itself gains -2 % on the arm swing;
        on Blender's capture with nothing hidden (seed 1), where the arm swing alone had come within 0.5 points of
        a false alarm, it gained +9.5 / -19 / +7 %: a mean of -1 %.

        With fewer than three folds "most" is every fold, and a fold counts only if it gains half of `min_gain`:
        a hair above zero is no evidence. Measured (session 51, `make demo`'s tiny capture with nothing hidden,
        two recordings): body friction gained 21.4 % without the arm swing and almost nothing without the walk
        (4.8 -> 4.8 mm), a mean of 10.7 %, and was accepted: a false alarm; with this rule the verdict is none (session
        52), and the tiny captures with a hidden tilt or air damping are still named (5 % or more in both folds)."""
        return not self.shortfalls(name, min_gain, min_gain_mm)

    def shortfalls(self, name: str, min_gain: float, min_gain_mm: float) -> list[str]:
        """Why `name` is not confirmed (CrossValidation.confirmed), one phrase per rule it fails; empty if none.

        Why in words: a `none` whose closest candidate fell just short (Blender's hidden wind on a two-recording
        tiny capture, session 53: +3.2 / +13.6 % over the folds, a mean of 8.4 %) is weak evidence a user should
        see, with what it lacked, instead of a bare "nothing missing" (verdict.closest)."""
        if not self.complete(name):
            return [f"refitted in {self.count(name)} of {len(self.folds)} folds: not among the split's finalists "
                    f"(a gain of {min_gain:.0%} on its held-out or training rollouts)"]
        g = self.per_fold(name)
        held = [", ".join(f.heldout) for f in self.folds if name in f.trials]
        failed = [h for h, row in zip(held, g) if not np.isfinite(row).all()]
        if failed:
            return [f"no finite rollout error with {' and '.join(failed)} held out"]
        out = []
        if g[:, 0].mean() < min_gain:
            out.append(f"mean held-out gain {g[:, 0].mean():+.1%}, under {min_gain:.0%}")
        if g[:, 2].mean() < 1e-3 * min_gain_mm:
            out.append(f"mean held-out improvement {1e3 * g[:, 2].mean():.2f} mm, under {min_gain_mm:g} mm")
        if len(g) < 3:
            weak = [h for h, gain in zip(held, g[:, 0]) if gain < 0.5 * min_gain]
            if weak:
                out.append(f"under {0.5 * min_gain:.0%} with {' and '.join(weak)} held out")
        elif 2 * (g[:, 0] > 0).sum() <= len(g):
            out.append(f"held-out rollouts better in {(g[:, 0] > 0).sum()} of {len(g)} folds")
        worse = [h for h, gain in zip(held, g[:, 1]) if gain <= 0]
        if worse:
            out.append(f"training rollouts worse with {' and '.join(worse)} held out")
        return out

    def ranked(self, passing: list[str]) -> list[str]:
        """Confirmed candidates in the order they are accepted: by the smaller of their mean gains on training and
        on held-out rollouts, then by the mean held-out gain, so a term must help every recording.

        Why not the training rollouts alone (sessions 21-22, on the user's split only): a slow wrong term can roll
        the training sequences out better while helping the held-out one less. Over 14 diagnoses at noise 0 the
        training gain chose 12 right, the smaller gain 13 (Blender's hidden wind, seed 2: gravity -20 % training /
        -11 % held-out, wind -14 % / -17 %); over 60 older ones both chose 39 right, the held-out gain alone 37
        (our simulator's hidden air damping: wind -3 % / -16 % against mass damping -32 % / -13 %)."""
        def key(n: str) -> tuple[float, float]:
            held, train = self.mean_gains(n)
            return -min(held, train), -held

        return sorted(passing, key=key)

    def separated(self, first: str, other: str, min_gain: float) -> bool:
        """`first` beats `other` on the smaller of its held-out and training-rollout gains in every fold that
        trialled both and whose held-out recording at least one of them improves by `min_gain` (the gain a
        confirmation needs), and there are two such folds or more (with 3 folds the strongest statement a sign
        test can make).

        Why not every fold: a held-out recording that neither improves by what a confirmation needs does not show
        the effect to either (the walk: the only recording with large swings, on which terms fitted to the twist
        and the arm swing carry over least), and which one helps it a little more says nothing about which is
        missing. Measured (Blender's hidden wind, seed 2, 20 steps; held-out / training gains per fold, wind
        against the tilt):
        - session 33: +29 / +23 % against +24 / +20 % without the arm swing, +18 / +14 against +14 / +13 % without
          the twist, -7.3 / +36 against -4.3 / +27 % without the walk; counting the walk's fold, the residual (the
          tilt selected, inclusion 0.82) named the tilt, a wrong class.
        - session 59 (current trials): +38.4 / +23.6 against +23.4 / +15.4 % without the arm swing, +37.5 / +20.9
          against +29.4 / +12.5 % without the twist, +0.4 / +20.9 against +5.8 / +14.1 % without the walk; counting
          that fold (both above zero) the two were not separated and the tilt, the selection's only choice, was
          named; counting it only from `min_gain` (10 %) names wind.
        - session 24's folds of the same capture (+17.4 / +14.2 against +11.0 / +19.5 %, +28.0 / +5.4 against
          +25.3 / +5.5 %, -2.3 / +13.6 against +6.5 / +20.0 % without the walk) stay unseparated either way (each
          better in one counted fold), and the residual names wind there; our simulator's tilt at 1.5 mm (session
          28), whose walk fold wind improves by 10.4 %, keeps that fold."""
        both = [f for f in self.folds if first in f.trials and other in f.trials
                and max(f.gains(first)[0], f.gains(other)[0]) >= min_gain]
        return len(both) >= 2 and all(min(f.gains(first)[:2]) > min(f.gains(other)[:2]) for f in both)

    def residual_tie_break(self, ranked: list[str], evidence: list[str], min_gain: float) -> list[str]:
        """`ranked` with its first place given to the candidate the residual regression ranks higher (`evidence`,
        in the regression's order; the diagnosis passes only what it selected, verdict.named_first) where the
        folds do not separate that candidate from the rollouts' first.

        Why: rollouts judge how much a term helps, the one-step residual what pattern of force is missing, and
        only the residual sees the pattern. Wind pressure and a gravity tilt both push a skirt sideways and roll
        out alike; on the residual, wind acts on the panels facing it and a tilt on every vertex by its mass.
        Measured (session 24, Blender's hidden wind, seed 2): the tilt came first on the rollouts (smaller mean
        gain 14.2 % against wind's 11.1 %) but was better in only 2 of 3 folds, by 0.1 point in one of them,
        while the forward selection chose wind alone (26 % of the residual explained, the tilt 20 %)."""
        if not ranked:
            return ranked
        lead = ranked[0]
        for n in evidence:
            if n == lead:
                break
            if n in ranked and not self.separated(lead, n, min_gain):
                return [n] + [m for m in ranked if m != n]
        return ranked

    def given_mean_gain(self, name: str) -> float | None:
        """Mean held-out gain over the folds of the trial given the truth `name`; None unless every fold has it."""
        if not all(name in f.given for f in self.folds):
            return None
        return float(np.mean([f.given_gain(name) for f in self.folds]))

    def to_json(self) -> dict:
        names = sorted({n for f in self.folds for n in f.trials})
        given = sorted({n for f in self.folds for n in f.given})
        return {"folds": [f.to_json() for f in self.folds],
                "candidates": {n: dict(zip(("heldout_gain", "train_rollout_gain"), self.mean_gains(n)),
                                       folds=self.count(n)) for n in names},
                "given_truth": {n: {"heldout_gain": self.given_mean_gain(n)} for n in given}}
