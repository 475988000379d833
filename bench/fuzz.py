"""A seeded fuzz campaign over OBJ/MTL, ``.vs3`` and points inputs, counted by outcome (issue 19).

    python bench/fuzz.py [--quick] [--obj 300 --vs3 200 --points 100 --seed 0]

Each mutant of the bundled scenes, the test suite's View3D models and a points file (see
``tests/fuzzing.py`` for the edits and what each one expects) runs through ``radiosity.cli.main``
in this process with a timeout. The table has issue 19's layout; ``bench/results/fuzz.json``
holds the counts and, for every run outside "solved" and "exit 2, one clean line", its edits
and what was seen, so a finding can be replayed (``--only KIND:INDEX``).
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent / "tests"))
sys.path.append(str(HERE.parent))
os.environ.setdefault("PYVISTA_OFF_SCREEN", "true")
os.environ.setdefault("RADIOSITY_MEMORY_BUDGET", "4G")  # a mutant must not take the shared machine's memory

from _common import parse_args, write_json  # noqa: E402

import fuzzing  # noqa: E402

KINDS = ("obj", "vs3", "points")
HEADERS = {"obj": "OBJ/MTL", "vs3": ".vs3", "points": "points"}


def _extra(parser) -> None:
    parser.add_argument("--obj", type=int, default=300)
    parser.add_argument("--vs3", type=int, default=200)
    parser.add_argument("--points", type=int, default=100)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--timeout", type=float, default=120.0, help="seconds per run")
    parser.add_argument("--only", default=None, help="replay one mutant, e.g. obj:17")


def campaign(counts: dict[str, int], seed: int, timeout: float, only: str | None = None) -> dict:
    bases = {}
    findings, table = [], {kind: dict.fromkeys(fuzzing.OUTCOMES, 0) for kind in KINDS}
    for kind in KINDS:
        cases = fuzzing.mutants(kind, counts[kind], seed)
        for index, mutant in enumerate(cases):
            if only and only != f"{kind}:{index}":
                continue
            key = (kind, mutant.base)
            if key not in bases and mutant.expect == "same":
                bases[key] = fuzzing.run_mutant(fuzzing.base_mutant(kind, mutant.base), timeout)
            t0 = time.perf_counter()
            run = fuzzing.run_mutant(mutant, timeout)
            outcome, why = fuzzing.classify(mutant, run, bases.get(key))
            table[kind][outcome] += 1
            seconds = time.perf_counter() - t0
            if outcome not in fuzzing.CLEAN_OUTCOMES or only:
                findings.append({"case": f"{kind}:{index}", "base": mutant.base, "edits": mutant.edits,
                                 "expect": mutant.expect, "outcome": outcome, "why": why, "exit": run.code,
                                 "seconds": round(seconds, 2)})
                print(f"  {kind}:{index} {outcome}: {mutant.edits} -> {why[:160]}", flush=True)
    return {"counts": table, "findings": findings}


def print_table(result: dict, counts: dict[str, int]) -> None:
    head = "| class | " + " | ".join(f"{HEADERS[k]} ({counts[k]})" for k in KINDS) + " |"
    print(head)
    print("|---|" + "---:|" * len(KINDS))
    for outcome in fuzzing.OUTCOMES:
        print(f"| {outcome} | " + " | ".join(str(result["counts"][k][outcome]) for k in KINDS) + " |")


def main(argv=None) -> None:
    args = parse_args(__doc__.splitlines()[0], argv, extra=_extra)
    counts = {"obj": args.obj, "vs3": args.vs3, "points": args.points}
    if args.quick:
        counts = {"obj": 40, "vs3": 30, "points": 15}
    t0 = time.perf_counter()
    result = campaign(counts, args.seed, args.timeout, args.only)
    result.update(seconds=round(time.perf_counter() - t0, 1), seed=args.seed, mutants=counts,
                  timeout_s=args.timeout)
    print_table(result, counts)
    print(f"{sum(counts.values())} mutants in {result['seconds']} s")
    if not args.only:
        write_json("fuzz", result, args.out)


if __name__ == "__main__":
    main()
