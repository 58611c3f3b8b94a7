"""Snakemake entry point: raw network depth (no scaling) of every frame of one scene, at the prepared size."""
import sys

sys.stderr = sys.stdout = open(snakemake.log[0], "w", buffering=1)  # noqa: F821  (log first)

# torch / BLAS threads from the configuration, not the executor, and deterministic kernels, before numpy
# and torch load: same seed -> same bits under any --cores or cluster (redsup.determinism)
from redsup.determinism import configure as deterministic_torch  # noqa: E402
deterministic_torch(snakemake.config["jobs"]["compute_threads"])  # noqa: F821

import time  # noqa: E402

import numpy as np  # noqa: E402
import torch  # noqa: E402

from redsup.depth import checkpoint, data  # noqa: E402
from redsup.depth.plan import model_parent  # noqa: E402
from redsup.depth.experiments import predict_sequence, resize_depth  # noqa: E402
from redsup.fileio import save_npz_atomic  # noqa: E402
from redsup.runlog import child_run  # noqa: E402

sm = snakemake  # noqa: F821
dev = sm.config["depth"]["device"]
device = dev if dev != "auto" else ("cuda" if torch.cuda.is_available() else "cpu")
name = f"{sm.wildcards.dataset}/{sm.wildcards.mode}/{sm.wildcards.scene}"
parent = model_parent(sm.config, f"{sm.wildcards.dataset}/{sm.wildcards.mode}")
with child_run(sm.log.run, parent, f"predict {name}", rule=sm.rule, wildcards=dict(sm.wildcards),
               config=sm.config) as run:
    models, meta = checkpoint.load(sm.input.model, device)
    images, K = data.read_prepared(sm.input.images)
    start = time.perf_counter()
    size = (int(meta["height"]), int(meta["width"]))  # a system trained at a reduced input size sees its size
    seq = data.resize_sequence(data.Sequence(name, images, K), size)
    depth = predict_sequence(models, seq.images, meta, device=device, K=seq.K)
    if size != images.shape[1:3]:  # back to the prepared size (the disparity resized, as the evaluation does)
        depth = np.stack([resize_depth(d, images.shape[1:3]) for d in depth]).astype(np.float32)
    seconds = time.perf_counter() - start
    save_npz_atomic(sm.output[0], depth=depth, K=K.astype(float))
    stats = {"frames": len(depth), "seconds_per_image": seconds / max(1, len(depth)),
             "median_depth": float(torch.as_tensor(depth).median()) if len(depth) else float("nan")}
    run.log_metrics(stats)
    print(stats)
