"""How many recorded Robotouille instances our seeded generator reproduces exactly.

For each recorded instance (``instances/<split>/<task>_<seed>.json``: the 200 benchmark ones,
and ``instances_train/<split>_train/<task>_26.json``: the two demonstration kitchens), the
problem file it was made from is randomised by ``workers.envs.robotouille.generator.generate``
at the recorded seed; a match needs the same ``used_seed`` and a ``generated_environment_json``
equal to the recorded one, key order included (compared as serialised JSON). Prints one line per
mismatch, then the counts, and exits 1 unless everything matches. Run from the repository root:

    .venv/bin/python bench/robotouille_generator.py [--data-dir DIR] [--write-manifest]

``--write-manifest`` also regenerates ``pipeline/manifests/robotouille-generated.sha256`` (the
digests ``recap data fetch``/``check`` pin for the generated instance files): needed only after a
deliberate change of the generator, the instance-file format or the engine's observation text.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from workers.envs.robotouille.data import resolve_data_dir  # noqa: E402
from workers.envs.robotouille.generator import generate  # noqa: E402

EXAMPLES = Path("environments/env_generator/examples")


def recorded(root: Path) -> list[tuple[str, Path]]:
    """(group, instance file) for every recorded instance, benchmark ones first."""
    found = [("benchmark", p) for p in sorted((root / "instances").glob("*/*.json"))]
    found += [("train", p) for p in sorted((root / "instances_train").glob("*/*.json"))]
    return found


def compare(root: Path, path: Path) -> str | None:
    """None when the instance is reproduced, else why not (one line)."""
    raw = json.loads(path.read_text(encoding="utf-8"))
    problem = json.loads((root / EXAMPLES / f"{raw['environment_name']}.json").read_text(encoding="utf-8"))
    got = generate(problem, int(raw["seed"]))
    if got.used_seed != raw["used_seed"]:
        return f"used seed {got.used_seed}, recorded {raw['used_seed']}"
    if json.dumps(got.problem) != json.dumps(raw["generated_environment_json"]):
        if got.problem == raw["generated_environment_json"]:
            return "same content, different key order"
        return "different kitchen"
    return None


def write_generated_manifest(root: Path) -> None:
    from pipeline.data import generated_manifest_file, sha256_file, write_manifest
    from workers.envs.robotouille.data_folders import FOLDER as ROBOTOUILLE
    from workers.envs.robotouille.generator import write_instances

    with tempfile.TemporaryDirectory() as tmp:
        written = write_instances(root, Path(tmp))
        write_manifest(generated_manifest_file(ROBOTOUILLE), {rel: sha256_file(Path(tmp) / rel) for rel in written})
    print(f"wrote {generated_manifest_file(ROBOTOUILLE)} ({len(written)} files)")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data-dir", help="Robotouille data folder (default: the usual search)")
    parser.add_argument("--write-manifest", action="store_true", help="rewrite the pinned digests of generated files")
    args = parser.parse_args()
    root = resolve_data_dir(args.data_dir)
    counts: dict[str, list[int]] = {"benchmark": [0, 0], "train": [0, 0]}
    start = time.perf_counter()
    for group, path in recorded(root):
        why = compare(root, path)
        counts[group][1] += 1
        if why is None:
            counts[group][0] += 1
        else:
            print(f"MISMATCH {path.relative_to(root)}: {why}")
    elapsed = time.perf_counter() - start
    for group, (ok, total) in counts.items():
        print(f"{group}: {ok}/{total} reproduced")
    print(f"time: {elapsed:.1f} s")
    if args.write_manifest:
        write_generated_manifest(root)
    return 0 if all(ok == total for ok, total in counts.values()) and counts["benchmark"][1] else 1


if __name__ == "__main__":
    sys.exit(main())
