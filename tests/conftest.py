"""Shared fixtures: the default config and a fresh run-folder path per test."""

from __future__ import annotations

import copy

import pytest

from sashil.config import default_config


@pytest.fixture
def config():
    """A fresh copy of the default config (simulated rig, seed parameters, 1 kHz)."""
    return copy.deepcopy(default_config())
