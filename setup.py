"""Map the root folders core/ and plugins/ under the one namespace ``asmteach``.

Every package below them is listed automatically; ``asmteach`` itself is an
implicit namespace package, so nothing named ``core`` or ``plugins`` is
installed at the top of site-packages.
"""

from setuptools import find_packages, setup

ROOTS = ("core", "plugins")
packages = [f"asmteach.{p}" for p in find_packages(include=[f"{r}*" for r in ROOTS[:1]] + [f"{ROOTS[1]}*"])]
setup(
    packages=packages,
    package_dir={f"asmteach.{r}": r for r in ROOTS},
)
