

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
