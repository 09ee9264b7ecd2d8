"""The event engine: every contact start and end and every friction mode change located, and
stepped between them (README "Friction as events"; docs/engine.md draws the stages).

Small numba functions over a few packed arrays (`collide.engine.layout`), because numba's compile
time grows with the number of arguments, array accesses and specialisations (measured: a
function of 200 array statements compiles in 10-20 s here; the same code split and packed, in a
tenth of that) and its cache loads in proportion to the code. Everything is 3D inside: a 1D or
2D scene lives in the z = 0 plane with spin about z, so one path serves every dimension.

From the top: run (`simulate`) -> windows -> island (`run_island`) -> locate (`step_events`) ->
substep (`step`, `kick`) -> forces (`friction`) -> contact (`slip`, `geometry`); an island of a
sphere alone on a wall -> rest (`rest_phase`).
"""
