"""The embedded, procedurally generated driving world.

Urban scenes in the canonical raw-scene format (README, "The canonical raw-scene format") and motorway velocity clips in the
TuSimple shape. Modules, from the bottom up:

- `common`: seeding, rotations, small maths helpers;
- `noise`: hashed value noise and band-limited fBm (textures are functions of position);
- `road`: the graded, cambered road surface (piecewise-quadratic profile, closed-form ray intersection);
- `prims`: oriented boxes and spheres of a frame, cars as body + glass cabin;
- `sensors`: pinhole cameras, the spinning LiDAR, per-domain rigs;
- `raycast`: vectorised ray casting with per-primitive screen-space culling;
- `textures`: materials (albedo, Cityscapes label, LiDAR reflectance) per surface;
- `shade`: camera images, label/instance/depth buffers; `lidar`: sweeps with glass pass-through;
- `ego`, `layout`: trajectories and procedural scene content; `gt`: ground-truth boxes;
- `generate`: `write_scene`; `motorway`, `clips`: `write_clips`.
"""
