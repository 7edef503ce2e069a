"""Built-extension tier: the zip validates (tags included), installs into a temporary Blender user folder,
enables, and its operators work from the installed copy."""
from __future__ import annotations

import json
import os
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

pytestmark = [pytest.mark.extension, pytest.mark.bpy]

ROOT = Path(__file__).resolve().parents[2]


def test_zip_installs_enables_and_imports(small_capture, tmp_path):
    build = subprocess.run([sys.executable, str(ROOT / "tools" / "build_addon.py"), "--out", str(tmp_path / "dist")],
                           capture_output=True, text=True, check=True)
    zip_path = Path(build.stdout.strip().splitlines()[-1])
    assert zip_path.name == "gaussian_garments-0.1.0.zip"
    names = zipfile.ZipFile(zip_path).namelist()
    assert {"blender_manifest.toml", "__init__.py", "blender_addon/jobs.py", "operators/import_capture.py",
            "gg_core/capture/layout.py"} <= set(names)
    assert not [n for n in names if n.startswith(("tests/", ".venv/", "out/", "tools/")) or "__pycache__" in n]

    user = tmp_path / "blender_user"
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(user), GG_PYTHON=sys.executable)
    proc = subprocess.run([sys.executable, str(Path(__file__).with_name("install_worker.py")), str(zip_path),
                           str(small_capture)], capture_output=True, text=True, env=env, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    found = json.loads(proc.stdout.strip().splitlines()[-1])
    assert found["installed"] == ["FINISHED"] and found["enabled"]
    assert found["preferences"] == "GG_AddonPreferences"
    assert Path(found["package_dir"]) == user / "extensions" / "user_default" / "gaussian_garments"
    assert found["imported"] == ["FINISHED"]
    assert found["collections"] == ["seq0"] and found["cameras"] == ["cam00", "cam01", "cam02"]
    # Nothing is written into the add-on folder: the body cache goes to the extension's user folder.
    cache = Path(found["body_cache"])
    assert cache.is_file()
    assert cache.is_relative_to(user / "extensions" / ".user" / "user_default" / "gaussian_garments")
    assert (found["job"], found["job_result"]) == (["FINISHED"], "gg inspect: done")


def test_bad_tag_fails_validation(tmp_path):
    source = tmp_path / "src"
    source.mkdir()
    (source / "__init__.py").write_text("")
    manifest = (ROOT / "blender_manifest.toml").read_text()
    (source / "blender_manifest.toml").write_text(manifest.replace('"Mesh"', '"Garments"'))
    proc = subprocess.run([sys.executable, "-c", "import sys; sys.path.insert(0, sys.argv[1]); import build_addon, "
                           "pathlib; build_addon.build(pathlib.Path(sys.argv[2]), pathlib.Path(sys.argv[3]))",
                           str(ROOT / "tools"), str(tmp_path / "dist"), str(source)], capture_output=True, text=True)
    assert proc.returncode != 0
    assert 'invalid tag "Garments"' in proc.stderr
