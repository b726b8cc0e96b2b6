import numpy as np
import pytest

import sjt_pin as sjt


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
