"""Vehicle velocity from tracked 2D boxes and from synthetic box tracks (McCraith ch. 3).

- `geometry`: eq. (1) (ground point of a box from the camera height, and back), the geometric baseline
  (the last-frame derivative of the reprojected points, or the slope of a line through the last few),
  `calibration.txt` reader; `diagnosis`: why that baseline fails, per distance bin;
- `data`: MedianFlow tracks of a clip split with ground truth and per-vehicle bad-input flags;
- `smoothing`: the temporal Gaussian filter g;
- `mlp`: the MLP with hand-written CReLU, features, training (Adam, exponential decay), timing;
- `synthetic`: the §IV-B generator fitted on the training clips;
- `metrics`: the TuSimple protocol (E_v per distance bin and overall, E_p);
- `experiment`: one configuration end to end; `summary`: our tables and Fig. 3 / Fig. 6;
- `tables`: the tables' frames and captions from the configurations' metrics (what `plan.table_frame`
  calls); it also writes each configuration's metrics / predictions files and saves the figures;
- `spread`: the relative-velocity spread per bin of a clip split (the clips' traffic model is measured by it);
- `select`: the knob sweep on the val clips.
"""
