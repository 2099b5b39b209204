

def machine() -> str:
    """The machine a benchmark ran on, for its report (architecture, cores, processor)."""
    import os
    import platform

    return f"{platform.machine()}, {os.cpu_count()} cores, {platform.processor() or platform.system()}"
