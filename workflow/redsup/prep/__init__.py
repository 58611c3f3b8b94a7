"""Data preparation: raw canonical scenes to training/evaluation inputs."""
