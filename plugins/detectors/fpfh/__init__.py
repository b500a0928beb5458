"""FPFH + RANSAC + ICP baseline detector (Open3D's global registration)."""
