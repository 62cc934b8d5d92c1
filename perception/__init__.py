"""Perception: the seed paper's geometric pipeline (Section III), OpenCV and numpy only.

observe.py   render colour + depth (optionally a noisy depth sensor)
crop.py      calibration crop from the projected plate / work volume
segment.py   HSV colour mask; Algorithm 1 (connected components, minimum area, erosion)
plane.py     colour-free alternative: RANSAC plate-plane removal
geometry.py  pinhole projection and back-projection
normals.py   PCA normals on the organised point cloud, facing the camera
grasps.py    Algorithm 2: vertical normals -> can centre, lying/upright, axis -> shared grasp rule
can_model.py the can model as a test on flat tops: height, an upright disc, a lying strip
can_discs.py can discs of known radius in a merged or partly hidden top (Hough + rim profile)
pipeline.py  perceive(scene) -> PerceptionResult
evaluate.py  matching to ground truth, grasps on distractors, and the accuracy figures
debug_images.py, bench.py   pictures for people; speed figures
"""
