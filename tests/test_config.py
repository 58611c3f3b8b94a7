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
