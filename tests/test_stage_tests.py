"""Every stage of the engine has its tests beside it: each module under collide/engine/ has a test
file at the mirrored path under tests/engine/ (collide/engine/event/rest.py:
tests/engine/event/test_rest.py), or is listed in UNMIRRORED with why it has none; and each test
file there mirrors a module that exists. So a change to a stage finds its tests, and a stage
added, renamed or moved without its tests is seen."""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
ENGINE = ROOT / "collide" / "engine"
TESTS = ROOT / "tests" / "engine"

# Engine modules (paths under collide/engine/) without a test file of their own, and why.
UNMIRRORED = {
    "layout.py": "columns, codes and constants, no code: every engine test reads them",
    "tier.py": "compiled or interpreted, and the cache's key: tests/test_tier.py, tests/test_engine_compile.py",
    "jit.py": "the decorators: compiled through in tests/test_engine_compile.py and tests/test_stale_cache.py",
    "hint.py": "the environment a command sets for the tier: tests/test_tier.py",
    "records.py": "no direct test: knots, records and intervals only through whole runs (tests/test_recording.py)",
    "event/run.py": "the entry (`simulate`): every event-engine run of the tests goes through it",
    "dem/layout.py": "columns, flags and codes, no code",
    "dem/geometry.py": "no direct test: the reduced quantities, through each law's test (tests/engine/dem/)",
    "dem/contact.py": "the laws composed: through each law's test (tests/engine/dem/)",
    "dem/forces.py": "no direct test: the force pass, through every DEM run",
    "dem/records.py": "no direct test: frames and energy parts, through the energy balances of tests/engine/dem/",
    "dem/loop.py": "the run loop: whole DEM runs (tests/test_contact_laws.py, tests/test_refusals.py)",
    "dem/barrier.py": "the threads' meetings: tests/engine/dem/test_threads.py (runs on 2 and 3 threads meet at it "
                      "twice a step and end with the one-thread run's bits; its meetings counted)",
}


def _modules() -> list[str]:
    return sorted(p.relative_to(ENGINE).as_posix() for p in ENGINE.rglob("*.py")
                  if p.name != "__init__.py" and "__pycache__" not in p.parts)


def _mirror(module: str) -> Path:
    path = Path(module)
    return TESTS / path.parent / f"test_{path.name}"


def test_every_engine_module_has_its_tests_at_the_mirrored_path_or_says_why() -> None:
    missing = [f"collide/engine/{m} (no {_mirror(m).relative_to(ROOT)})" for m in _modules()
               if m not in UNMIRRORED and not _mirror(m).is_file()]
    assert _modules() and not missing, ("engine modules without tests at the mirrored path (add them there, or list "
                                        "the module in UNMIRRORED with why): " + "; ".join(missing))


def test_the_allow_list_names_only_modules_that_exist_without_tests() -> None:
    stale = [f"{m}: " + ("has " + _mirror(m).relative_to(ROOT).as_posix() if _mirror(m).is_file() else "no such module")
             for m in UNMIRRORED if m not in _modules() or _mirror(m).is_file()]
    assert not stale, "UNMIRRORED entries to remove: " + "; ".join(stale)


def test_every_stage_test_file_mirrors_a_module() -> None:
    """A test file under tests/engine/ named test_X.py sits where collide/engine/ has X.py."""
    modules = set(_modules())
    orphans = [p.relative_to(ROOT).as_posix() for p in sorted(TESTS.rglob("test_*.py"))
               if (p.parent.relative_to(TESTS) / p.name.removeprefix("test_")).as_posix() not in modules]
    assert not orphans, "test files under tests/engine/ with no module at the mirrored path: " + "; ".join(orphans)
