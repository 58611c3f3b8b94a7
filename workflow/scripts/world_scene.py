"""Snakemake entry point: render one scene of the embedded world in the canonical format."""
import sys

sys.stderr = sys.stdout = open(snakemake.log[0], "w", buffering=1)  # noqa: F821

from redsup.runlog import child_run  # noqa: E402
from redsup.world.generate import write_scene  # noqa: E402

sm = snakemake  # noqa: F821
spec = sm.config["datasets"][sm.wildcards.dataset]
split, index = sm.wildcards.scene.split("_")
with child_run(sm.log.run, "world", f"{sm.wildcards.dataset}/{sm.wildcards.scene}", rule=sm.rule,
               wildcards=dict(sm.wildcards), config=sm.config,
               params={"domain": spec["domain"], "split": split, "index": int(index)}) as run:
    summary = write_scene(sm.config["world"], dataset=sm.wildcards.dataset, domain=spec["domain"],
                          split=split, index=int(index), seed=sm.config["seed"], out_dir=sm.output[0])
    run.log_metrics(summary)
    print(summary)
