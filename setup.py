"""The compiled kernels, built by ``pip install``, never at run time (everything else about the
package is in pyproject.toml):

- ``sjt_pin.kernels._kernels``: plain C on the CPython API (sjt_pin/kernels/src/*.c, one file
  per idea);
- ``sjt_pin.kernels._distances``: coal's distance queries in C++ (src/distances.cpp), against
  the libcoal, Eigen and Boost headers and libraries the build environment's cmeel wheels hold
  (pyproject.toml's build requirements). Optional: where it cannot be built the collision
  limit queries through Pinocchio's Python bindings instead (slower, the same distances).
"""

import sys
from pathlib import Path

import numpy
from setuptools import Extension, setup

HERE = Path(__file__).resolve().parent
SOURCES = sorted(path.relative_to(HERE).as_posix()
                 for path in (HERE / "sjt_pin/kernels/src").glob("*.c"))
assert SOURCES, "the kernels' C sources (sjt_pin/kernels/src/*.c) are missing"

kernels = Extension(
    "sjt_pin.kernels._kernels", SOURCES,
    depends=["sjt_pin/kernels/src/kernels.h", "sjt_pin/kernels/src/distances.h"],
    include_dirs=[numpy.get_include()],  # args.c reads numpy's arrays in place
    # one module's files: only PyInit__kernels is visible outside the shared object
    extra_compile_args=["-O2", "-std=c99", "-fvisibility=hidden"])


def cmeel_prefix() -> Path | None:
    """The cmeel prefix (headers and libraries of the libcoal, cmeel-eigen and cmeel-boost
    wheels) on this interpreter's path, or None."""
    for entry in sys.path:
        prefix = Path(entry) / "cmeel.prefix"
        if ((prefix / "include/coal/config.hh").is_file()
                and (prefix / "include/eigen3/Eigen").is_dir()):
            return prefix
    return None


def distances(prefix: Path) -> Extension:
    boost_python = f"boost_python{sys.version_info.major}{sys.version_info.minor}"
    return Extension(
        "sjt_pin.kernels._distances", ["sjt_pin/kernels/src/distances.cpp"],
        depends=["sjt_pin/kernels/src/distances.h"], language="c++",
        include_dirs=[str(prefix / "include"), str(prefix / "include/eigen3")],
        library_dirs=[str(prefix / "lib")], libraries=["coal", boost_python],
        # installed beside cmeel.prefix in site-packages; an editable install's module finds
        # the libraries already loaded by `import coal` (sjt_pin.kernels imports it first)
        runtime_library_dirs=["$ORIGIN/../../cmeel.prefix/lib"],
        extra_compile_args=["-O2", "-std=c++17", "-fvisibility=hidden", "-g0",
                            "-Wno-deprecated-declarations"], optional=True)


PREFIX = cmeel_prefix()
if PREFIX is None:
    print("sjt-pin: no libcoal and Eigen headers on the path: the compiled distance queries "
          "are not built", file=sys.stderr)
setup(ext_modules=[kernels] + ([distances(PREFIX)] if PREFIX is not None else []))
