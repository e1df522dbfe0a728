"""Puts the MuJoCo library of the PyPI `mujoco` wheel where afs's build and binaries find it.

The README's test command runs this after `pip install -r examples/python/requirements.txt`
(which installs `mujoco==3.17.0`): it links the wheel's `libmujoco.so.3.17.0` as
`target/mujoco/libmujoco.so` (the name the `mujoco-rs` build script looks for; the folder is
`MUJOCO_DYNAMIC_LINK_DIR` in .cargo/config.toml) and under its versioned name (the name the
binaries load at run time, found through the rpath that .cargo/config.toml sets). Nothing to
export. Run it again after upgrading the wheel.
"""

import pathlib
import sys

WANTED = "3.17.0"


def main() -> int:
    try:
        import mujoco
    except ImportError:
        print(
            "mujoco_link.py: the Python package `mujoco` is missing; run "
            "`pip install -r examples/python/requirements.txt` first",
            file=sys.stderr,
        )
        return 2
    if mujoco.__version__ != WANTED:
        print(
            f"mujoco_link.py: mujoco {mujoco.__version__} is installed, afs is built against "
            f"{WANTED}; run `pip install mujoco=={WANTED}`",
            file=sys.stderr,
        )
        return 2
    wheel = pathlib.Path(mujoco.__file__).resolve().parent
    library = wheel / f"libmujoco.so.{WANTED}"
    if not library.is_file():
        print(f"mujoco_link.py: {library} is missing from the wheel", file=sys.stderr)
        return 2
    root = pathlib.Path(__file__).resolve().parents[2]
    # Always the workspace's target/ (MUJOCO_DYNAMIC_LINK_DIR); with CARGO_TARGET_DIR elsewhere
    # the binaries need LD_LIBRARY_PATH=<workspace>/target/mujoco (docs/mujoco.md).
    folder = root / "target" / "mujoco"
    folder.mkdir(parents=True, exist_ok=True)
    for name in ("libmujoco.so", library.name):
        link = folder / name
        if link.is_symlink() or link.exists():
            link.unlink()
        link.symlink_to(library)
    print(f"mujoco_link.py: {folder} -> {library}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
