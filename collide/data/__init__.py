"""Sample data shipped with collide.

`spring_runs/run01.csv` ... `run10.csv`: force probe + motion detector runs of a stress ball
for `collide fit-spring` (the report's section I). THESE DATA ARE SYNTHETIC: the report's raw
files were not published, so `scripts/make_spring_data.py` generates runs with the report's
statistics (true k = 1500 N/m, per-run slopes scattered like its Fig 2, 6-50 N, R^2 ~ 0.98)
from a fixed seed. They are not measurements. Read them with
`importlib.resources.files("collide.data") / "spring_runs"` (see `collide.fitting.sample_files`).
"""
