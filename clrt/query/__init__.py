"""Batch ray queries on the device: closest, any, count and all hits, camera
images, closest points of a mesh, signed distances and winding numbers
(``points.py``, ``inside.py``), and a drop-in for trimesh's intersector.

``rays.py`` (the rays a query takes), ``accel.py`` (:class:`Accel`: a mesh
uploaded once, queried often), ``results.py`` (what queries return),
``api.py`` (one-call forms), ``intersector.py`` (trimesh's interface),
``aov.py`` (camera images written as files).
"""

from clrt.query.accel import Accel
from clrt.query.api import (all_hits, any_hit, camera_images, closest_points, contains, count_hits, distance,
                            occluded, sdf_grid, signed_distance, trace, winding_number)
from clrt.query.results import AllHits, CameraImages, ClosestPoints, Hits

__all__ = ["Accel", "AllHits", "CameraImages", "ClosestPoints", "Hits", "all_hits", "any_hit", "camera_images",
           "closest_points", "contains", "count_hits", "distance", "occluded", "sdf_grid", "signed_distance", "trace",
           "winding_number"]
