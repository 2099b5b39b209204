"""The consumer library's own pieces: the command's entry point, the costmap of a release's map,
optional packages, the embodiments as package data."""
import subprocess
import sys

import numpy as np
import pytest


def navarena(*args):
    return subprocess.run([sys.executable, "-m", "navarena", *args], capture_output=True, text=True, timeout=300)


def test_command_prints_help_version_and_refuses_unknown_commands():
    p = navarena()
    assert p.returncode == 0 and "usage: navarena COMMAND" in p.stdout and "verify-release" in p.stdout
    v = navarena("--version")
    assert v.returncode == 0 and v.stdout.startswith("navarena 0.1.0") and "commit " in v.stdout
    bad = navarena("bogus")
    assert bad.returncode == 2 and "unknown command 'bogus'" in bad.stderr


def test_inflated_map_keeps_the_map_and_rebuilds_the_clearance():
    from navcore.nav.costmap import Costmap

    occ = np.ones((9, 12), bool)
    occ[2:7, 1:11] = False  # a free room 5 cells tall
    cm = Costmap.from_inflated_map(occ, (0.0, 0.0), 0.05, radius=0.18)
    assert np.array_equal(cm.occupancy, occ)  # the valid cells are the map's free cells, no more, no less
    # the centre row is 2.5 cells from the boundary half way to the walls: radius + 2.5 * 0.05
    assert cm.clearance[4, 5] == pytest.approx(0.18 + 0.125)
    assert cm.clearance[2, 5] == pytest.approx(0.18 + 0.025)  # beside the wall
    assert cm.clearance[1, 5] == pytest.approx(0.18 - 0.025)  # the first occupied row
    # a state half way between two free cells is valid, one half way into the wall is not
    assert cm.is_state_valid(0.05 * 6.0, 0.05 * 4.5) and not cm.is_state_valid(0.05 * 6.0, 0.05 * 1.6)


def test_optional_package_error_names_the_feature_and_the_extra(monkeypatch):
    from navcore.optional import require

    monkeypatch.setitem(sys.modules, "gsplat", None)  # as if not installed
    with pytest.raises(ImportError, match=r"renderer backend .* needs the package 'gsplat'.*navarena\[gpu\]"):
        require("gsplat", "renderer backend 'gsplat'")
    assert require("numpy", "anything") is np


def test_a_command_without_its_media_extra_says_what_to_install_in_one_line(tmp_path):
    """Videos and figures are the media extra's (a consumer venv without PyAV and matplotlib is about
    180 MB smaller): render-episodes without PyAV exits 2 before it reads anything, with one line
    naming the extra, and writes no output folder."""
    code = ("import sys; sys.modules['av'] = None\n"
            "from navarena.cli import main\n"
            f"main(['render-episodes', '--root', {str(tmp_path / 'nowhere')!r}, '--out', {str(tmp_path / 'out')!r}])")
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert p.returncode == 2, p.stderr
    assert p.stderr.strip().splitlines() == [
        "navarena render-episodes: navarena render-episodes (its videos) needs the package 'av', which is not "
        'installed: it comes with the media extra: pip install "navarena[media]"']
    assert not (tmp_path / "out").exists()


def test_embodiments_are_package_data_with_checked_keys(tmp_path, monkeypatch):
    import navcore.nav.embodiment as emb

    assert {"locobot", "stretch"} <= set(emb.embodiment_names())
    assert emb.load_embodiment("stretch").radius == pytest.approx(0.24)
    with pytest.raises(ValueError, match="unknown embodiment 'walle'; known: locobot"):
        emb.load_embodiment("walle")
    (tmp_path / "odd.yaml").write_text("name: odd\nradius: 0.2\nwheels: 3\n")
    monkeypatch.setattr(emb, "EMBODIMENT_DIR", tmp_path)
    with pytest.raises(ValueError, match=r"odd.yaml: unknown key\(s\) wheels"):
        emb.load_embodiment("odd")
