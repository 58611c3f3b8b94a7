"""Self-supervised monocular depth (Monodepth2-style), test-time instance adaptation and road-plane calibration.

Modules (each pure and small; import the one you need, nothing is re-exported here):

- ``networks``    ResNet-18 encoder (hand-written, random init), U-Net depth decoder, pose decoder, ``disp_to_depth``
- ``warping``     back-projection, projection, axis-angle poses, bilinear warping with ``grid_sample``
- ``losses``      per-pixel SSIM / photometric error, minimum reprojection, auto-masking, edge-aware smoothness
- ``pipeline``    the composition used by training and adaptation: predictions -> warps -> loss dict
- ``evaluation``  the KITTI Eigen protocol (Garg crop, median scaling, the seven metrics), skipped-frame reasons
- ``adaptation``  module-group selection (McCraith ch. 4 Table 1), frozen BatchNorm, SGD adaptation,
                  instance-wise vs sequential, direct optimisation of the outputs
- ``calibration`` road points, Least-Median-of-Squares plane fit, scale from the camera height (ch. 5) and baselines
- ``checkpoint``  trained networks on disk: ``save`` (atomic) and ``load(path) -> (models, meta)``
- ``data``        prepared camera sequences -> training / test samples (missing neighbours reported, static
                  frames, stereo partner, back camera in reversed temporal order, flips)
- ``training``    the Monodepth2 training loop (Adam, step decay)
- ``configs``     the tables' configurations as data (torch-free): rows, shared runs, captions
- ``experiments`` runners of one configuration: instance-wise / sequential adaptation, direct optimisation
- ``tables``      tables (rows averaged over common frames) and Figs. 4-5 from the runs' per-frame records
"""
