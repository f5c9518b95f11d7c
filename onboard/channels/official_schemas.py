"""Foxglove's official JSON Schemas of the ``foxglove.*`` types the recorder writes, read from
the copies in ``foxglove_jsonschema/`` (unmodified files of the ``@foxglove/schemas``
release named in its ``VERSION``; see its README). ``--update [version]`` refreshes them from
that package with ``npm pack`` (the one maintained publication of the JSON Schemas: the
foxglove-sdk Python package ships only Protobuf and FlatBuffers descriptors)."""

from __future__ import annotations

import argparse
import functools
import json
import subprocess
import sys
import tarfile
import tempfile
from pathlib import Path

DIR = Path(__file__).with_name("foxglove_jsonschema")
# the foxglove.* types the recorder writes (file stem = the name without "foxglove.")
TYPES = (
    "PoseInFrame",
    "FrameTransforms",
    "SceneUpdate",
    "CompressedImage",
    "CameraCalibration",
    "ImageAnnotations",
    "Log",
)


def version() -> str:
    return (DIR / "VERSION").read_text().strip()


@functools.cache
def official_schema(name: str) -> dict:
    """The official JSON Schema of ``foxglove.<Type>`` (a KeyError for another name)."""
    stem = name.removeprefix("foxglove.")
    if not name.startswith("foxglove.") or stem not in TYPES:
        raise KeyError(f"no official Foxglove schema kept for {name!r}")
    return json.loads((DIR / f"{stem}.json").read_text())


_EXTRACT = (
    "const s=require(process.argv[1]);"
    "process.stdout.write(JSON.stringify(Object.fromEntries(process.argv.slice(2)"
    ".map(k=>[k,s[k]]))))"
)


def update(pkg_version: str) -> None:
    """Replace the copies with those of ``@foxglove/schemas@<pkg_version>``."""
    with tempfile.TemporaryDirectory() as tmp:
        spec = f"@foxglove/schemas@{pkg_version}"
        out = subprocess.run(
            ["npm", "pack", spec, "--json"], cwd=tmp, check=True, capture_output=True, text=True
        )
        meta = json.loads(out.stdout)[0]
        with tarfile.open(Path(tmp) / meta["filename"]) as tar:
            tar.extractall(tmp, filter="data")
        index = str(Path(tmp) / "package" / "dist" / "jsonschema" / "index.js")
        got = subprocess.run(
            ["node", "-e", _EXTRACT, index, *TYPES], check=True, capture_output=True, text=True
        )
        schemas = json.loads(got.stdout)
    for stem in TYPES:
        if not schemas.get(stem):
            raise SystemExit(f"{spec} has no JSON Schema for foxglove.{stem}")
        (DIR / f"{stem}.json").write_text(json.dumps(schemas[stem], indent=2) + "\n")
    (DIR / "VERSION").write_text(meta["version"] + "\n")
    official_schema.cache_clear()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--update", metavar="VERSION", nargs="?", const="latest")
    args = ap.parse_args(argv)
    if args.update:
        update(args.update)
    print(f"@foxglove/schemas {version()}: {', '.join(TYPES)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
