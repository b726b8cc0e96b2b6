"""The compiled kernels (plain C on the CPython API, sjt_pin/kernels/src/: one file per idea):
built by ``pip install``, never at run time. Everything else about the package is in
pyproject.toml."""

from pathlib import Path

import numpy
from setuptools import Extension, setup

HERE = Path(__file__).resolve().parent
SOURCES = sorted(path.relative_to(HERE).as_posix()
                 for path in (HERE / "sjt_pin/kernels/src").glob("*.c"))
assert SOURCES, "the kernels' C sources (sjt_pin/kernels/src/*.c) are missing"

setup(ext_modules=[Extension(
    "sjt_pin.kernels._kernels", SOURCES, depends=["sjt_pin/kernels/src/kernels.h"],
    include_dirs=[numpy.get_include()],  # args.c reads numpy's arrays in place
    # one module's files: only PyInit__kernels is visible outside the shared object
    extra_compile_args=["-O2", "-std=c99", "-fvisibility=hidden"])])
