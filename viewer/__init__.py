"""`collide view`: a viser web viewer for live parameter scrubbing and replaying recordings.

Layers (only `app`, `session`, `scene3d` and `plots` import viser):

- `params`: which controls a scene needs, their safe ranges and clamping, building the scene.
- `state`: `ViewRun`, what to draw at any time t (frames, plot series, residuals, paths).
- `geometry`: meshes, the compressed sphere, orientations, the camera fit.
- `ensemble`: a small batch around the current parameters (`run_scenes`).
- `files`: recordings folder, uploads, safe names.
- `worker`: `LatestWorker`, one thread that always runs the newest request.
- `scene3d`, `plots`: drawing into viser's scene and uPlot charts.
- `session`: one browser tab (controls, timeline, worker, player); `app`: the server.
"""
