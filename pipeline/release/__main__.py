"""navarena release [--root DATA] [--out DIR] [--version X.Y.Z] [--previous DIR] [--catalog FILE]
[--internal] [--copy] [hydra overrides ...]

Builds the release of a finished data root. The overrides are those the root was made with (the
release refuses a root whose stages are not done for this config, naming each scene and stage);
release.* keys set the release's options (release.eval_set.size=..., release.extra_licenses=[...])."""
from __future__ import annotations

import argparse
import sys


def compose(overrides: list[str]):
    from hydra import compose as hydra_compose
    from hydra import initialize_config_dir

    from pipeline.config import CONF_DIR, register_configs

    register_configs()
    with initialize_config_dir(config_dir=str(CONF_DIR), version_base="1.3"):
        return hydra_compose("config", overrides=overrides)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="navarena release", description=__doc__.split("\n\n")[1],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--root", help="the finished data root (data_root; default: the config's, data)")
    ap.add_argument("--out", help="release folder (default {root}/11_releases/{name}-v{version})")
    ap.add_argument("--version", help="MAJOR.MINOR.PATCH (release.version)")
    ap.add_argument("--previous", help="the previous release's folder: release notes, unchanged files reused")
    ap.add_argument("--catalog", help="scenes.catalog the root was made from (default catalogs/synthetic.yaml)")
    ap.add_argument("--internal", action="store_true", help="release.public=false: keep every scene, marked internal")
    ap.add_argument("--copy", action="store_true",
                    help="release.copy_files=true: copy every file (an independent release; by default files are hard "
                         "links shared with the data root and the previous release)")
    ap.add_argument("overrides", nargs="*", help="Hydra overrides, as given to `make dataset`")
    a = ap.parse_args(argv)
    over = list(a.overrides)
    for flag, key in ((a.root, "data_root"), (a.version, "release.version"), (a.previous, "release.previous"),
                      (a.catalog, "scenes.catalog"), (a.out, "release.out")):
        if flag:
            over.append(f"{key}={flag}")
    if a.internal:
        over.append("release.public=false")
    if a.copy:
        over.append("release.copy_files=true")
    from pipeline.release.build import ReleaseError, build_release

    try:
        build_release(compose(over))
    except (ReleaseError, ValueError, FileNotFoundError) as e:
        print(f"navarena release: {e}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
