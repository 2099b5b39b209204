"""The `navarena` command line: subcommands with a help that fits a screen, `inspect` on a scene file
before any run, `doctor`."""
import dataclasses
import json
import subprocess
import sys

import numpy as np
import pytest

from navarena.cli import CONSUMER


def navarena(*args, timeout=300):
    return subprocess.run([sys.executable, "-m", "navarena", *args], capture_output=True, text=True, timeout=timeout)


def test_help_lists_every_command_and_each_help_fits_a_screen():
    p = navarena("--help")
    assert p.returncode == 0 and "run" in p.stdout
    from pipeline.config_reference import command_help

    h = navarena("inspect", "--help")  # the entry point dispatches to the command's own help ...
    assert h.returncode == 0 and h.stdout.startswith("usage: navarena inspect [-h]"), h.stderr[-500:]
    for name in [*CONSUMER, "release"]:  # ... which, in a 100-column terminal, fits a screen (in-process: no interpreter each)
        assert f"\n  {name} " in p.stdout
        lines = command_help(name).splitlines()
        assert lines[0].startswith(f"usage: navarena {name}"), name
        assert len(lines) <= 40 and max(map(len, lines)) <= 100, name
    bad = navarena("bogus")
    assert bad.returncode == 2 and "unknown command 'bogus'" in bad.stderr


@pytest.fixture(scope="module")
def tilted_scene(small_scene, tmp_path_factory):
    """The generated room stored with -y up (its +z turned onto -y) as SPZ, and the same in centimetres."""
    from navcore.gaussians.formats.spz import write_spz

    t = np.eye(4)
    t[:3, :3] = [[1, 0, 0], [0, 0, -1], [0, 1, 0]]  # z -> -y
    d = tmp_path_factory.mktemp("inspect")
    metres = small_scene.gaussians.transformed(t @ np.linalg.inv(small_scene.transform))  # canonical (z up), then -y up
    write_spz(d / "room.spz", metres)
    write_spz(d / "room_cm.spz", dataclasses.replace(metres, means=metres.means * 100,
                                                     log_scales=metres.log_scales + np.log(100).astype(np.float32)))
    return d


def test_inspect_finds_the_up_axis_and_the_units(tilted_scene, small_scene):
    from navarena.inspect_scene import main

    p = navarena("inspect", str(tilted_scene / "room.spz"), "--json", "--picture", str(tilted_scene / "top.png"))
    assert p.returncode == 0, p.stderr[-1000:]
    info = json.loads(p.stdout)
    assert info["format"] == "spz" and info["gaussians"] == len(small_scene.gaussians)
    assert info["up_axis"] == "-y" and abs(info["up_vector"][1] + 1) < 1e-3
    assert 2.3 < info["floor_to_top_m"] < 2.8 and info["units_hint"] == "plausible for metres"
    assert (tilted_scene / "top.png").stat().st_size > 10_000
    cm = navarena("inspect", str(tilted_scene / "room_cm.spz"), "--json", "--picture", str(tilted_scene / "cm.png"))
    assert "centimetres" in json.loads(cm.stdout)["units_hint"]
    assert main([str(tilted_scene / "missing.spz")]) == 2


def test_inspect_without_the_media_extra_prints_its_facts_and_says_why_no_picture(tilted_scene, monkeypatch, capsys):
    """matplotlib is the media extra's: without it, inspect still gives the format, size, up axis and
    units, and names the extra where the picture would be."""
    import sys

    from navarena.inspect_scene import main

    monkeypatch.setitem(sys.modules, "matplotlib", None)  # as if not installed
    assert main([str(tilted_scene / "room.spz"), "--json", "--picture", str(tilted_scene / "none.png")]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["up_axis"] == "-y" and info["units_hint"] == "plausible for metres"
    assert info["picture"].startswith("none (") and 'pip install "navarena[media]"' in info["picture"]
    assert not (tilted_scene / "none.png").exists()


def test_inspect_says_file_not_found(tmp_path, capsys):
    from navarena.inspect_scene import main

    assert main([str(tmp_path / "nothing.ply")]) == 2
    assert "file not found" in capsys.readouterr().err


def test_doctor_reports_the_core_of_this_machine():
    p = navarena("doctor", "--json")
    checks = {c["name"]: c for c in json.loads(p.stdout)}
    assert p.returncode == 0, [c for c in checks.values() if c["core"] and not c["ok"]]
    assert {"python", "packages", "torch", "gpu", "gsplat", "ompl", "detector weights"} <= set(checks)
    assert all(c["detail"] for c in checks.values())
    assert checks["detector weights"]["ok"] and checks["packages"]["ok"]
    assert checks["pipeline packages"]["ok"], checks["pipeline packages"]  # make setup installs the pipeline group


def test_doctor_names_what_the_pipeline_group_lacks(monkeypatch):
    """From a checkout, the pipeline's dependency group (pyproject.toml, markers evaluated) is
    checked too: a distribution missing from it is named (an offline make setup-gpu installs only
    its wheel folder; the evaluate stage's results check needs jsonschema)."""
    import navarena.doctor as doctor

    names, missing = doctor.pipeline_group()
    assert {"ompl", "jsonschema", "hydra-core", "dask"} <= set(names) and missing == []
    assert ("open3d" in names) != ("open3d-cpu" in names)  # one of the two, by the platform's marker
    real = doctor._version
    monkeypatch.setattr(doctor, "_version", lambda d: None if d == "jsonschema" else real(d))
    check = next(c for c in doctor.checks() if c.name == "pipeline packages")
    assert not check.ok and "missing: jsonschema (" in check.detail and f"{len(names) - 1} of {len(names)}" in check.detail


def test_ctrl_c_in_any_command_exits_130_without_a_traceback(monkeypatch, capsys):
    import navarena.doctor
    from navarena import cli

    def interrupted(argv):
        raise KeyboardInterrupt

    monkeypatch.setattr(navarena.doctor, "main", interrupted)
    with pytest.raises(SystemExit) as e:
        cli.main(["doctor"])
    assert e.value.code == 130
    err = capsys.readouterr().err
    assert "navarena doctor: interrupted" in err and "Traceback" not in err


def test_doctor_passes_a_consumer_install_without_the_pipelines_packages(monkeypatch, capsys):
    """navarena doctor on a library install (no checkout, no OMPL or OpenCV): exit 0, the pipeline
    reported as not here and its packages not counted as failures, hints a pip user can follow; from
    a checkout the same missing OMPL fails it."""
    import navarena.doctor as doctor

    real_try = doctor._try
    monkeypatch.setattr(doctor, "_try", lambda m: (False, "ModuleNotFoundError") if m in ("ompl", "cv2") else real_try(m))
    monkeypatch.setattr(doctor, "pipeline_group", lambda: None)
    assert doctor.main([]) == 0
    out = capsys.readouterr().out
    assert "the library (navcore, navarena)" in out and "the pipeline: not here" in out
    assert "FAIL" not in out and "make setup" not in out.split("the pipeline")[0].replace("make setup-gpu", "")
    monkeypatch.setattr(doctor, "pipeline_group", lambda: (["ompl"], ["ompl"]))
    assert doctor.main([]) == 1
    assert "FAIL" in capsys.readouterr().out


def test_inspect_draws_the_aligned_frame_the_costmap_picture_draws(tmp_path, monkeypatch):
    """One orientation (issue 86): a file with -y up whose content runs along its x axis is drawn with that
    run left to right, as the costmap picture of its aligned frame draws it (x right, y up), not turned 90
    degrees; both pictures say their frame."""
    import matplotlib.pyplot as plt

    from navarena import inspect_scene
    from navcore.io.map_picture import FRAME_NOTE, topdown_picture

    rng = np.random.default_rng(0)
    m = np.column_stack([rng.uniform(0, 6, 4000), rng.uniform(-0.1, 0.1, 4000), rng.uniform(0, 1, 4000)])  # long in x
    seen = {}
    real_imshow = plt.Axes.imshow

    def imshow(self, img, *a, extent=None, **k):
        seen["extent"] = extent
        return real_imshow(self, img, *a, extent=extent, **k)

    monkeypatch.setattr(plt.Axes, "imshow", imshow)
    titles = []
    monkeypatch.setattr(plt.Axes, "set_title", lambda self, t, **k: titles.append(t))
    inspect_scene.picture(m, "room.ply", str(tmp_path / "top.png"), {"up_vector": [0, -1, 0], "up_axis": "-y"})
    u0, u1, v0, v1 = seen["extent"]
    assert u1 - u0 > 5 and v1 - v0 < 2  # the 6 m run is horizontal on the page
    assert FRAME_NOTE in titles[0]
    import navcore.io.map_picture as mp

    notes = []
    monkeypatch.setattr(mp, "annotated", lambda img, res, legend, note=None, **k: notes.append(note) or img)
    topdown_picture(np.zeros((4, 6), bool), np.ones((4, 6), bool), np.zeros((4, 6), bool), None, 0.05, "locobot")
    assert FRAME_NOTE in notes[0]
