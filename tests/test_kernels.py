"""pipeline.kernels: which kernel caches are stale (the check `make test` runs before compiling
the CPU kernels once for all its workers)."""
import os

from pipeline.kernels import kernel_modules, stale


def test_stale_kernel_caches_known_answers(tmp_path):
    kern = "import numba\n\n@numba.njit(cache=True)\ndef f(x):\n    return x\n"
    (tmp_path / "navcore" / "render").mkdir(parents=True)
    (tmp_path / "stages").mkdir()
    comp = tmp_path / "navcore" / "render" / "composite.py"
    other = tmp_path / "stages" / "other.py"
    plain = tmp_path / "stages" / "plain.py"
    comp.write_text(kern)
    other.write_text(kern)
    plain.write_text("x = 1  # no kernel\n")
    assert kernel_modules(tmp_path) == [comp, other]
    # a fresh checkout: the renderer's compositing kernel has no cache; one never called does not count
    assert stale(tmp_path) == [comp]
    for f in (comp, other):
        (f.parent / "__pycache__").mkdir(exist_ok=True)
        (f.parent / "__pycache__" / f"{f.stem}.f-3.py311.nbi").write_bytes(b"")
    assert stale(tmp_path) == []
    t = os.stat(other).st_mtime
    os.utime(other.parent / "__pycache__" / "other.f-3.py311.nbi", (t - 10, t - 10))  # source edited since
    assert stale(tmp_path) == [other]
