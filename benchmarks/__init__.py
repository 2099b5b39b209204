

def machine() -> str:
    """The machine a benchmark ran on, for its report (architecture, cores, processor)."""
    import os
    import platform

    return f"{platform.machine()}, {os.cpu_count()} cores, {platform.processor() or platform.system()}"


def write_report(out, name: str, rep: dict, omit=()):
    """Write a benchmark's JSON report to out/name and print it without the keys in `omit`
    (the bulky per-item parts); returns the file's path."""
    import json
    from pathlib import Path

    from navcore.io import jsonio

    path = Path(out) / name
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(jsonio.dumps(rep, indent=1, default=str))
    print(json.dumps({k: v for k, v in rep.items() if k not in omit}, indent=1, default=str))
    return path


def run_polled(cmd: list[str], log, cwd=None, env=None, interval: float = 0.2) -> dict:
    """Run cmd with its output in `log`: wall seconds, the process's peak RSS in MiB (polled every
    `interval` s) and its exit code."""
    import subprocess
    import time
    from pathlib import Path

    import psutil

    log = Path(log)
    log.parent.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    with open(log, "w") as f:
        p = subprocess.Popen(cmd, cwd=cwd, stdout=f, stderr=subprocess.STDOUT, env=env)
        proc, peak = psutil.Process(p.pid), 0
        while p.poll() is None:
            try:
                peak = max(peak, proc.memory_info().rss)
            except psutil.Error:
                pass
            time.sleep(interval)
    return {"wall_s": time.perf_counter() - t0, "peak_rss_mb": peak / 2**20, "exit": p.returncode}
