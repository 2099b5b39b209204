"""Fault injection (slow; `make test-faults`): each scenario of benchmarks.faults against an
undisturbed reference run, asserting that every injected fault was survived and every stored
byte matches. The full-disk scenario needs root (it mounts a tmpfs) and is skipped otherwise."""
import pytest

from benchmarks import faults

pytestmark = [pytest.mark.slow, pytest.mark.faults]


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    work = tmp_path_factory.mktemp("faults")
    return faults.reference(work), work


@pytest.mark.parametrize("name", list(faults.SCENARIOS))
def test_fault_is_survived_and_outputs_match(name, reference):
    ref, work = reference
    d = work / name
    d.mkdir()
    r = faults.SCENARIOS[name](ref, d, 6) if name == "kill_run" else faults.SCENARIOS[name](ref, d)
    if r.get("skipped"):
        pytest.skip(r["skipped"])
    assert r["injected"] > 0, r
    assert r["survived"] == r["injected"], r
    assert r["byte_mismatches"] == 0, r["mismatched_files"]
