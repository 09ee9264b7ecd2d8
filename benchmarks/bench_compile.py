"""Where the engine's first compile spends its CPU: per function and by phase. Runs the warm-up
(`collide.warmup.compile_now`) in this process into a fresh numba cache and prints Markdown tables.

    .venv/bin/python benchmarks/bench_compile.py [--top 25] [--passes] [--keep DIR]

Every CPU second of the compile is given to one function (the innermost one numba is compiling)
and one phase: numba's front end (type inference, its other IR passes, lowering to LLVM IR) or
LLVM (parsing the IR, per-function optimisation, linking the callees' libraries, module
optimisation, machine code), or saving to the cache. `--passes` adds LLVM's own pass timings
summed over all libraries (numba's NUMBA_LLVM_PASS_TIMINGS; it slows the compile by a third).
`--keep DIR` compiles into DIR (which must not hold a compile of this source yet) and keeps it.
"""

from __future__ import annotations

import os
import sys
import tempfile

if __name__ == "__main__":
    _keep = sys.argv[sys.argv.index("--keep") + 1] if "--keep" in sys.argv else None
    os.environ["NUMBA_CACHE_DIR"] = _keep or tempfile.mkdtemp(prefix="bench-compile-")
    os.environ["COLLIDE_JIT"] = "1"
    os.environ["COLLIDE_COMPILING"] = "1"  # this process compiles: no lock, no background compile
    if "--passes" in sys.argv:
        os.environ["NUMBA_LLVM_PASS_TIMINGS"] = "1"

import argparse
import collections
import functools
import shutil
import time

# numba's passes grouped into the front end's phases.
_TYPING = {"nopython_type_inference", "partial_type_inference", "nopython_rewrites"}
_LOWERING = {"native_lowering", "nopython_backend"}
_INLINING = {"inline_inlinables", "inline_overloads", "inline_closure_likes"}


def _phase_of_pass(name: str) -> str:
    if name in _TYPING:
        return "typing"
    if name in _LOWERING:
        return "lowering"
    if name in _INLINING:
        return "inlining"
    return "numba other"


class Profile:
    """Exclusive CPU time per (function, phase), from nested frames."""

    def __init__(self) -> None:
        self.frames: list[list] = []  # [phase, function, started, children]
        self.seconds: dict[tuple[str, str], float] = collections.defaultdict(float)
        self.compiles: collections.Counter = collections.Counter()
        self.typed: collections.Counter = collections.Counter()
        self.dispatchers: dict[str, object] = {}

    def function(self) -> str:
        return next((f[1] for f in reversed(self.frames) if f[0] == "numba other"), "(outside)")

    def push(self, phase: str, function: str | None = None) -> None:
        self.frames.append([phase, function or self.function(), time.process_time(), 0.0])

    def pop(self) -> None:
        phase, function, started, children = self.frames.pop()
        spent = time.process_time() - started
        self.seconds[function, phase] += spent - children
        if self.frames:
            self.frames[-1][3] += spent

    def wrap(self, owner: type, name: str, phase: str) -> None:
        original = getattr(owner, name)

        @functools.wraps(original)
        def timed(*args, **kwargs):
            self.push(phase)
            try:
                return original(*args, **kwargs)
            finally:
                self.pop()

        setattr(owner, name, timed)


def _name(dispatcher) -> str:
    function = dispatcher.py_func
    return f"{function.__module__.removeprefix('collide.engine.')}.{function.__qualname__}"


def instrument(profile: Profile) -> None:
    from numba.core import caching, codegen, event

    class Compiles(event.Listener):
        def on_start(self, ev) -> None:
            name = _name(ev.data["dispatcher"])
            profile.compiles[name] += 1
            profile.dispatchers[name] = ev.data["dispatcher"]
            profile.push("numba other", name)

        def on_end(self, ev) -> None:
            profile.pop()

    class Passes(event.Listener):
        def on_start(self, ev) -> None:
            name = ev.data["name"].split(" [")[0]
            if name == "nopython_type_inference":
                profile.typed[ev.data["qualname"]] += 1
            profile.push(_phase_of_pass(name))

        def on_end(self, ev) -> None:
            profile.pop()

    event.register("numba:compile", Compiles())
    event.register("numba:run_pass", Passes())
    library = codegen.CPUCodeLibrary
    profile.wrap(library, "add_ir_module", "llvm parse")
    profile.wrap(library, "_optimize_functions", "llvm function opt")
    profile.wrap(codegen.JITCodeLibrary, "finalize", "llvm link")
    profile.wrap(library, "_optimize_final_module", "llvm module opt")
    profile.wrap(codegen.JITCodeLibrary, "_finalize_specific", "llvm machine code")
    profile.wrap(caching.Cache, "save_overload", "cache save")


PHASES = ["typing", "inlining", "numba other", "lowering", "llvm parse", "llvm function opt", "llvm link",
          "llvm module opt", "llvm machine code", "cache save"]


def _table(profile: Profile, top: int) -> None:
    per_function: dict[str, dict[str, float]] = collections.defaultdict(lambda: collections.defaultdict(float))
    for (function, phase), seconds in profile.seconds.items():
        per_function[function][phase] += seconds
    totals = {p: sum(f[p] for f in per_function.values()) for p in PHASES}
    front = ["typing", "inlining", "numba other", "lowering"]
    short = ["typing", "inline", "numba", "lower", "parse", "fn opt", "link", "mod opt", "mcode", "save"]
    print(f"| function | compiles | typed | total | {' | '.join(short)} |")
    print("|---|---|---|---|" + "---|" * len(PHASES))
    ranked = sorted(per_function.items(), key=lambda kv: -sum(kv[1].values()))
    for function, phases in ranked[:top]:
        qualname = function.split(".", 1)[-1].rsplit(".", 1)[-1] if "." in function else function
        typed = max((n for q, n in profile.typed.items() if q.rsplit(".", 1)[-1] == qualname), default=0)
        cells = " | ".join(f"{phases[p]:.1f}" for p in PHASES)
        print(f"| {function} | {profile.compiles[function]} | {typed} | {sum(phases.values()):.1f} | {cells} |")
    rest = ranked[top:]
    print(f"| ({len(rest)} more) | {sum(profile.compiles[f] for f, _ in rest)} | | "
          f"{sum(sum(p.values()) for _, p in rest):.1f} | "
          + " | ".join(f"{sum(p[ph] for _, p in rest):.1f}" for ph in PHASES) + " |")
    print(f"| **all** | {sum(profile.compiles.values())} | | {sum(totals.values()):.1f} | "
          + " | ".join(f"{totals[p]:.1f}" for p in PHASES) + " |")
    llvm = sum(v for p, v in totals.items() if p.startswith("llvm"))
    print(f"\nfront end {sum(totals[p] for p in front):.1f} s, LLVM {llvm:.1f} s, cache save "
          f"{totals['cache save']:.1f} s; {len(per_function)} functions, {sum(profile.compiles.values())} compiles")
    inlined = sorted(q for q, n in profile.typed.items() if n > 1)
    if inlined:
        print("typed more than once (inlined at several sites, or compiled and inlined): "
              + ", ".join(f"{q} x{profile.typed[q]}" for q in inlined))


def _passes(profile: Profile, top: int) -> None:
    """LLVM's pass timings summed over every compiled overload (user CPU)."""
    by_pass: dict[str, float] = collections.defaultdict(float)
    by_stage: dict[str, float] = collections.defaultdict(float)
    for dispatcher in profile.dispatchers.values():
        for sig in dispatcher.signatures:
            timings = dispatcher.get_metadata(sig).get("llvm_pass_timings")
            for named in timings or []:
                stage = named.name if not named.name.startswith("Function passes") else "Function passes"
                records = named.timings.list_records()
                for record in records[:-1]:
                    by_pass[record.pass_name] += record.user_time
                if records:
                    by_stage[stage] += records[-1].user_time
    print("\n| LLVM stage | user s |\n|---|---|")
    for stage, seconds in sorted(by_stage.items(), key=lambda kv: -kv[1]):
        print(f"| {stage} | {seconds:.1f} |")
    print("\n| LLVM pass | user s |\n|---|---|")
    for name, seconds in sorted(by_pass.items(), key=lambda kv: -kv[1])[:top]:
        print(f"| {name} | {seconds:.1f} |")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--top", type=int, default=25)
    parser.add_argument("--passes", action="store_true", help="also LLVM's pass timings")
    parser.add_argument("--keep", help="compile into this folder and keep it")
    args = parser.parse_args()
    profile = Profile()
    started = time.process_time()
    from collide.engine import jit  # noqa: F401  (numba set up as the engine sets it up)

    instrument(profile)
    from collide.warmup import compile_now

    compile_now()  # the warm-up's compile, marked ready (a kept cache is used as it is)
    spent = time.process_time() - started
    cache = os.environ["NUMBA_CACHE_DIR"]
    size = sum(os.path.getsize(os.path.join(d, f)) for d, _, fs in os.walk(cache) for f in fs)
    from numba.core import config

    print(f"compile: {spent:.1f} s of CPU in this process, cache {size / 1e6:.1f} MB, "
          f"NUMBA_OPT {int(config.OPT)}, loop vectorize {config.LOOP_VECTORIZE}, "
          f"SLP vectorize {config.SLP_VECTORIZE}\n")
    _table(profile, args.top)
    if args.passes:
        _passes(profile, args.top)
    if not args.keep:
        shutil.rmtree(cache, ignore_errors=True)


if __name__ == "__main__":
    main()
