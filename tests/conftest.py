import os

import numpy as np
import pytest
from hypothesis import settings

import sjt_pin as sjt

# Property tests are derandomised by default, so a commit that changed nothing cannot fail CI;
# `pytest --hypothesis-profile=fuzz` (or HYPOTHESIS_PROFILE=fuzz) draws new examples instead.
settings.register_profile("ci", derandomize=True, print_blob=True)
settings.register_profile("fuzz", derandomize=False, print_blob=True)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "ci"))


@pytest.fixture(scope="session")
def ur5() -> sjt.Robot:
    return sjt.Robot.from_example("ur5")


@pytest.fixture(scope="session")
def panda() -> sjt.Robot:
    return sjt.Robot.from_example("panda")


@pytest.fixture(scope="session")
def planar3() -> sjt.Robot:
    return sjt.Robot.planar3()


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(12345)


@pytest.fixture(scope="module")
def chromium():
    """Debian's headless Chromium (tests/browser.py), one per test module; a loud skip where it
    is not installed."""
    from .browser import Chromium

    browser = Chromium()
    yield browser
    browser.close()
