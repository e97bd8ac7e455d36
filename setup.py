"""Only here because setuptools takes `cffi_modules` from setup(); all metadata is in pyproject.toml."""

from setuptools import setup

setup(
    cffi_modules=[
        "src/topdress/ecu/_build.py:ffibuilder",
        "src/topdress/isobus/_build.py:ffibuilder",
    ]
)
