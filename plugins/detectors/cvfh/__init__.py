"""CVFH + CRH + ICP depth detector (``cvfh_icp``); its descriptors live in :mod:`.descriptors`."""
