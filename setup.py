"""The compiled kernels (plain C on the CPython API): built by ``pip install``, never at run time.
Everything else about the package is in pyproject.toml."""

from setuptools import Extension, setup

setup(ext_modules=[Extension("sjt_pin.kernels._kernels", ["sjt_pin/kernels/_kernels.c"],
                             extra_compile_args=["-O2", "-std=c99"])])
