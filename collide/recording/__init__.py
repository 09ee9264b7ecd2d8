"""Rerun recordings of runs: one `.rrd` per run, written in bulk and read back losslessly.

This is the only package in `collide/` that imports rerun (docs/design.md section 5). A recording
holds three things:

- what a person looks at, on one timeline `sim_time` (simulated seconds): spheres with spin
  markers and trails, contact points with normal and friction force arrows, compression,
  energies, momentum, angular momentum and their residuals, the scene and the run settings, and
  a blueprint (3D view beside the plots);
- what a program reads back: the trajectory exactly (float64 knots: each body's state at the
  ends of its steps and of its free flight, with its accelerations; each contact's forces at each
  step; the contact intervals) under `/collide/knots`, `/collide/contact_records` and
  `/collide/contact_intervals`, and the run's settings under `/collide/meta`, from which
  `read_recording` rebuilds the `SceneRun`;
- a seal, `/collide/integrity`: the SHA-256 of every byte of the file (its own 64 digits read as
  zeros), so that any changed byte, of what the viewer draws or of what is read back, makes the
  file refused.

Frames: plots (energies, momenta, compression, residuals) are drawn at the steps' ends: every
contact step (or every `stride`-th; each contact's first and last step always) and a steady
`fps` in free flight, where the motion is known in closed form. Where islands step apart, one's
step end falls inside another's step, whose bodies are interpolated there: residuals are drawn
only where every body's state is exact (`diagnostics.settled`). The 3D view adds at least
`contact_frames` frames across each contact, interpolated between steps, so a contact taken in
a few long steps still animates smoothly. Each entity is written with one `send_columns` call
(the trajectory's tables 65 536 rows a call, the drawn contacts of many a block of frames a
call); static data with one `log`. The file is written as it is logged (`stream`). Entities a scene
does not need are absent: no friction without friction, no spin when nothing spins, no walls
without walls, no angular momentum in 1D, no contact entity for a contact that never happened.

Entity paths (`<b>` a body name, `<c>` a contact such as `ball1-ball2` or `ball1-wall0`):

============================================  ==============================================
/world/<b>                                    Ellipsoids3D: the sphere (turns with the body)
/world/<b>/spin                               LineStrips3D: centre-to-rim marker (spinning)
/world/<b>/trail                              LineStrips3D: path so far (a segment a frame)
/world/walls/wall<k>                          LineStrips3D: a wall (static)
/world/contacts/<c>/point                     Points3D: contact point while in contact
/world/contacts/<c>/normal_force              Arrows3D: force on each body (force_scale m/N)
/world/contacts/<c>/friction_force            Arrows3D: friction on each body
/contacts/<c>/compression                     Scalars m: each sphere's compression
/contacts/<c>/overlap                         Scalars m
/contacts/<c>/normal_force                    Scalars N: magnitude
/contacts/<c>/friction_force                  Scalars N: magnitude
/energy/kinetic, spring, total                Scalars J
/energy/rotational                            Scalars J (when something spins)
/energy/gravitational                         Scalars J (with gravity)
/energy/dissipated, total_plus_dissipated     Scalars J (with friction, damping or rolling resistance)
/energy/dissipated_damping, _friction, _rolling, tangential_spring   Scalars J (DEM runs: each part)
/momentum                                     Scalars kg m/s, one series per axis
/angular_momentum                             Scalars kg m^2/s about the origin (2D, 3D)
/spin/<b>                                     Scalars rad/s (when something spins)
/residuals/energy, momentum, angular_momentum  Scalars, relative, as in the JSON summary
/scene                                        TextDocument: the scene TOML (static)
/settings                                     TextDocument: run settings (static)
/world/bodies                                 Points3D: every sphere (scenes of many bodies)
/world/contacts/points, normal_force          every contact at once (scenes of many contacts)
/collide/meta                                 AnyValues: settings and shapes for read-back
/collide/knots, contact_records, ...          AnyValues float64: the trajectory, exactly
/collide/integrity                            AnyValues: sha256 of every byte of the file (last)
============================================  ==============================================

Modules: `writer` (write_recording; what a person looks at is drawn by `draw`, at the times of
`frames`, in columns built by `columns`), `reader` (reading in this process), `sandbox`
(read_recording and verify_recording: in a child process unless trusted), `integrity` (the
.rrd framing and the seal), `spec` (the format's names and version, the checksum) and
`accuracy` (a work-precision study as a recording). The names below are the public API.
"""

from typing import Any

from collide.recording.sandbox import (
    SAFE_MEMORY_MB,
    SAFE_TIMEOUT_S,
    read_recording,
    read_recording_safely,
    verify_recording,
)
from collide.recording.spec import (
    APP_ID,
    DISSIPATION_PARTS,
    FORMAT,
    FORMAT_VERSION,
    INTEGRITY,
    TIMELINE,
    RecordingError,
    checksum,
    collide_version,
)

# Imported when first asked for: writing imports Rerun (0.7-1 s), which a process that only
# reads (the viewer opening a recording, whose reader process imports it) need not wait for.
_LAZY = {"write_accuracy_recording": "accuracy", "frame_times": "frames", "entity_paths": "reader",
         **{name: "writer" for name in ("CONTACT_FRAMES", "DEFAULT_FPS", "MANY_BODIES", "MANY_CONTACTS",
                                        "MAX_FREE_FRAMES", "MAX_RECORDED_TIME", "SEAL_ATTEMPTS", "WriteStats",
                                        "last_write", "write_recording")}}


def __getattr__(name: str) -> Any:
    if name not in _LAZY:
        raise AttributeError(f"module 'collide.recording' has no attribute '{name}'")
    import importlib

    return getattr(importlib.import_module(f"collide.recording.{_LAZY[name]}"), name)


__all__ = ["APP_ID", "CONTACT_FRAMES", "DEFAULT_FPS", "DISSIPATION_PARTS", "FORMAT", "FORMAT_VERSION", "INTEGRITY",
           "MANY_BODIES", "MANY_CONTACTS", "MAX_FREE_FRAMES", "MAX_RECORDED_TIME", "SAFE_MEMORY_MB", "SAFE_TIMEOUT_S",
           "SEAL_ATTEMPTS", "TIMELINE", "RecordingError", "WriteStats", "checksum", "collide_version", "entity_paths",
           "frame_times", "last_write", "read_recording", "read_recording_safely", "verify_recording",
           "write_accuracy_recording", "write_recording"]
