"""Configuration: schema errors name the key; profiles only override known keys."""
from pathlib import Path

import pytest

from redsup import config

ROOT = Path(__file__).resolve().parents[1]


def test_every_profile_resolves():
    for profile in config.PROFILES:
        cfg = config.load(ROOT / "config.yaml", {"profile": profile})
        assert cfg["profile"] == profile and "profiles" not in cfg


def test_misspelled_key_is_named():
    with pytest.raises(config.ConfigError, match="camras"):
        config.load(ROOT / "config.yaml", {"prepare": {"camras": ["cam_front"]}})


def test_unknown_profile_override_is_named():
    with pytest.raises(config.ConfigError, match="profiles.tiny.prepar"):
        config.load(ROOT / "config.yaml", {"profiles": {"tiny": {"prepar": {}}}})


def test_bad_value_is_named():
    with pytest.raises(config.ConfigError, match="depth_range"):
        config.load(ROOT / "config.yaml", {"prepare": {"depth_range": [-1.0, 80.0]}})


def test_unknown_profile_name():
    with pytest.raises(config.ConfigError, match="profile"):
        config.load(ROOT / "config.yaml", {"profile": "huge"})


def test_hash_is_stable_and_sensitive():
    a = config.load(ROOT / "config.yaml", {"profile": "tiny"})
    b = config.load(ROOT / "config.yaml", {"profile": "tiny"})
    c = config.load(ROOT / "config.yaml", {"profile": "default"})
    assert config.config_hash(a) == config.config_hash(b) != config.config_hash(c)


def test_every_profile_crops_and_resizes_the_world_without_distortion():
    # the prepared image keeps the aspect of the crop: a profile that scales the raw frames must scale the crop
    # and the resize with them (the paper profile once kept the default's 208 x 64 on 3x frames: 2.4 x vs 1.6 x)
    for profile in config.PROFILES:
        cfg = config.load(ROOT / "config.yaml", {"profile": profile})
        for name, spec in cfg["datasets"].items():
            if spec["kind"] != "world":
                continue
            raw, crop, out = cfg["world"]["domains"][spec["domain"]], spec["crop"], spec["resize"]
            cut_w = raw["width"] - crop["left"] - crop["right"]
            cut_h = raw["height"] - crop["top"] - crop["bottom"]
            sx, sy = cut_w / out["width"], cut_h / out["height"]
            assert sx == pytest.approx(sy, rel=0.02), f"{profile} {name}: {cut_w} x {cut_h} -> {out}"
