"""The fixed-step DEM kernel: the contact laws of docs/design.md section 9, stepped as DEM codes
step them, one file per stage (as LAMMPS' src/GRANULAR: one file per force kind, small stateless
kernels, a composer):

- `layout`: the columns, flags and status codes of the kernel's arrays (no numba: the Python
  side, `collide.dem`, reads them without loading the engine);
- `normal`, `damping`, `tangential`, `rolling`: the laws, one function each;
- `geometry`: reduced mass, radius and inertia, wall heights, the contact point's velocity;
- `contact`: one contact's forces, composed from the laws the scene uses;
- `forces`: the force pass over the listed contacts, each contact's start and end;
- `neighbours`: the Verlet lists (cell grid, body-wall pairs, history carried over);
- `verlet`: the half kicks and drifts (with the work each force part does);
- `flight`: free flight in closed form where nothing touches;
- `records`: frames and energy parts;
- `loop`: `dem_run`, the run from start to end.

Nothing is re-exported here: import the module you need.
"""
