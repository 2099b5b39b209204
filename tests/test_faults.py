"""Fault injection (slow; `make test-faults`): each scenario of faults.faults against an
undisturbed reference run, asserting that every injected fault was survived and every stored
byte matches. The full-disk scenario needs root (it mounts a tmpfs) and is skipped otherwise.

NAVARENA_FAULTS_KILLS sets the whole-run kill points (6 here, 20 in `make test-faults`);
NAVARENA_FAULTS_REPORT names a bench_faults.json the module writes the scenarios' figures to, so
that `make test-faults` runs each scenario once (the benchmark then merges the fuzzing figures);
NAVARENA_FAULTS_WORK moves the work folder (/tmp/navarena_faults, shared with the benchmark: its
reference run is reused while the code that made it is today's)."""
import json
import os
from pathlib import Path

import pytest

from faults import faults

pytestmark = [pytest.mark.slow, pytest.mark.faults]


@pytest.fixture(scope="module")
def reference():
    """The reference lives in faults' work folder, reused while the code is unchanged."""
    work = Path(os.environ.get("NAVARENA_FAULTS_WORK", "/tmp/navarena_faults"))
    work.mkdir(parents=True, exist_ok=True)
    return faults.reference(work), work


@pytest.fixture(scope="module")
def report():
    scenarios: dict = {}
    yield scenarios
    out = os.environ.get("NAVARENA_FAULTS_REPORT")
    if out and scenarios:
        Path(out).parent.mkdir(parents=True, exist_ok=True)
        Path(out).write_text(json.dumps({"scenarios": scenarios}, indent=1))


@pytest.mark.parametrize("name", list(faults.SCENARIOS))
def test_fault_is_survived_and_outputs_match(name, reference, report):
    ref, work = reference
    r = faults.run_scenario(name, ref, work, kills=int(os.environ.get("NAVARENA_FAULTS_KILLS", "6")))
    report[name] = r
    if r.get("skipped"):
        pytest.skip(r["skipped"])
    assert r["injected"] > 0, r
    assert r["survived"] == r["injected"], r
    assert r["byte_mismatches"] == 0, r["mismatched_files"]
