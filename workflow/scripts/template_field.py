"""Snakemake entry point: the template car's distance field of one stage (lifting, ch. 6; lidar_detector, ch. 7),
built once and read by every training job of the stage."""
import sys

sys.stderr = sys.stdout = open(snakemake.log[0], "w", buffering=1)  # noqa: F821  (log first)

import time  # noqa: E402

from redsup.det3d.template import build_template, save_template, spec_from_config  # noqa: E402

sm = snakemake  # noqa: F821
spec = spec_from_config(sm.config[sm.wildcards.stage])
start = time.perf_counter()
template = build_template(spec, workers=sm.threads)
save_template(sm.output[0], template)
print(f"{sm.wildcards.stage}: {spec}: {len(template.points)} surface points, field {tuple(template.field.shape)} "
      f"(z, y, x), {time.perf_counter() - start:.2f} s")
