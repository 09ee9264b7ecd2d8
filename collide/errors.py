"""Errors of a run, importable without the engine (the engine decides compiled or interpreted
kernels when it is first imported, see `collide.engine.tier`)."""

from __future__ import annotations


class RunError(RuntimeError):
    """A run that cannot be trusted: unstable step, blow-up, non-finite numbers, runaway length."""


class SawtoothError(RunError):
    """The islands met a tangential spring's sawtooth at a falling cap, which DEM takes instead."""
