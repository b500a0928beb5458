"""asmteach-gantry: a robot plugin package made outside asmteach, on its core contracts only.

It registers ``gantry`` in the ``asmteach.robots`` entry-point group (see
``tests/thirdparty_robot/conftest.py``, which installs it as a distribution).
"""
