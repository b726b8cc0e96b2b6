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


#: a revolute-prismatic-revolute arm (a telescoping link, as on a SCARA or a Panda's fingers
#: under joint 7): how far the slide is out sets how far the first joint swings the links below
REVOLUTE_PRISMATIC_URDF = """<robot name="revolute_prismatic">
<link name="base"/>
<link name="l1"><collision><origin xyz="0.15 0 0"/><geometry><box size="0.3 0.06 0.06"/>
 </geometry></collision></link>
<link name="l2"><collision><geometry><sphere radius="0.05"/></geometry></collision></link>
<link name="l3"><collision><origin xyz="0.12 0 0"/><geometry><box size="0.24 0.04 0.04"/>
 </geometry></collision></link>
<joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><axis xyz="0 0 1"/>
 <limit lower="-3" upper="3" effort="1" velocity="2"/></joint>
<joint name="j2" type="prismatic"><parent link="l1"/><child link="l2"/><axis xyz="1 0 0"/>
 <limit lower="0" upper="1.5" effort="1" velocity="1"/></joint>
<joint name="j3" type="revolute"><parent link="l2"/><child link="l3"/>
 <origin xyz="0 0 0.1"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="2"/>
</joint>
</robot>"""


@pytest.fixture(scope="session")
def revolute_prismatic() -> sjt.Robot:
    return sjt.Robot.from_urdf(REVOLUTE_PRISMATIC_URDF, ee_frame="l3")


@pytest.fixture(scope="session")
def continuous_wrist() -> sjt.Robot:
    """The revolute-prismatic arm with its last joint continuous: q (cos, sin) is not its own
    tangent space."""
    urdf = REVOLUTE_PRISMATIC_URDF.replace('<joint name="j3" type="revolute">',
                                           '<joint name="j3" type="continuous">')
    return sjt.Robot.from_urdf(urdf.replace('name="revolute_prismatic"',
                                            'name="continuous_wrist"'), ee_frame="l3")
