"""Build step of the compiled kernel candidate (everything else is in pyproject.toml)."""

import numpy
from setuptools import Extension, setup

setup(
    ext_modules=[
        Extension(
            "idkit.optim._ckernel",
            ["idkit/optim/_ckernel.c"],
            include_dirs=[numpy.get_include()],  # numpy/random/bitgen.h
            extra_compile_args=["-O3", "-ffp-contract=off"],
            optional=True,
        )
    ]
)
