"""Depth perception shared by the detector plugins (``cvfh_icp``, ``fpfh_ransac``) and the robots.

- :mod:`~asmteach.core.perception.depth_camera`: the virtual Kinect v1 (renders depth frames of meshes);
- :mod:`~asmteach.core.perception.segmentation`: input checks, table removal, clustering
  (:mod:`~asmteach.core.perception.concave` cuts clusters at concave creases,
  :mod:`~asmteach.core.perception.scene_labels` labels every point of a scene,
  :mod:`~asmteach.core.perception.segment_score` scores such labels);
- :mod:`~asmteach.core.perception.registration`: ICP refinement and hypothesis verification;
- :mod:`~asmteach.core.perception.viewpoint`: the camera centre a detection uses, and its stage clock;
- :mod:`~asmteach.core.perception.second_view`: other depth views judge the rival poses one view left ambiguous;
- :mod:`~asmteach.core.perception.open3d_tools`: Open3D point clouds and its thread limit.

Frames: world (metres, z up) unless a docstring says otherwise.
"""
