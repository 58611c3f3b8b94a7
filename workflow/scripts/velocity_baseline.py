"""Snakemake entry point: a configuration of McCraith ch. 3 without learning (the geometric baseline of
eq. (1), or the constant training-mean reference) evaluated on the test splits."""
import sys

sys.stderr = sys.stdout = open(snakemake.log[0], "w", buffering=1)  # noqa: F821  (log first)

from pathlib import Path  # noqa: E402

from redsup.runlog import child_run  # noqa: E402
from redsup.velocity import plan  # noqa: E402
from redsup.velocity.data import load_split  # noqa: E402
from redsup.velocity.experiment import run_constant, run_geometric  # noqa: E402
from redsup.velocity.tables import write_configuration_outputs  # noqa: E402

sm = snakemake  # noqa: F821
vcfg = sm.config["velocity"]
configuration = plan.configurations(sm.config)[sm.params.run["configuration"]]
with child_run(sm.log.run, plan.parent(sm.config, configuration["name"]), sm.wildcards.run, rule=sm.rule,
               wildcards=dict(sm.wildcards), config=sm.config,
               params={"configuration": configuration, "tables": sm.params.run["tables"], "geometric": vcfg["geometric"],
                       "min_box_px": vcfg["min_box_px"]}) as run:
    splits = {Path(c).name: load_split(t, c, vcfg["min_box_px"]) for t, c in zip(sm.input.tracks, sm.input.clips)}
    if configuration["method"] == "geometric":
        metrics, predictions = run_geometric(splits, fps=sm.config["velocity_clips"]["fps"],
                                             window=vcfg["geometric"]["window"],
                                             timing_repeats=vcfg["mlp"]["timing_repeats"])
    else:
        train = load_split(sm.input.train_tracks, sm.input.train_clips, vcfg["min_box_px"])
        metrics, predictions = run_constant(train, splits)
    write_configuration_outputs(configuration, metrics, predictions, splits, sm.output.metrics, sm.output.predictions)
    run.log_metrics(metrics)
    print(metrics)
