"""`collide view`: a viser web viewer for live parameter scrubbing and replaying recordings.

Layers (the first ones never import viser):

- `params`: which controls a scene needs, their safe ranges and clamping, building the scene.
- `state`: `ViewRun`, what to draw at any time t (frames, plot series, residuals, paths).
- `geometry`: meshes, the compressed sphere, orientations, the camera fit.
- `ensemble`: a small batch around the current parameters (`run_scenes`).
- `files`: recordings folder, uploads, safe names.
- `worker`: `LatestWorker`, one thread that always runs the newest request.
- `scene3d`, `plots`: drawing into viser's scene and uPlot charts.
- `config`: `SessionConfig`, what a tab needs from the app.
- `panel` (the fixed controls), `messages` (the text lines in them), `param_controls` (the
  Parameters folder), `playback` (time, Timeline, player thread), `camera` (the camera fit),
  `live` (runs with changed parameters, previews, background runs), `ensemble_view`,
  `file_actions` (those folders): the parts of a tab.
- `session`: one browser tab, joining its parts; `tabs`: the tabs' life cycles; `app`: the server.
"""
