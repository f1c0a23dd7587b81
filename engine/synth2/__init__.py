"""A second, independently written family of synthetic 360-degree worlds (issue 13, 1a).

Floor plans of rooms, corridors, junctions, crossings and a plaza (``routes.py``), walls
textured with crops of real photographs (``textures.py``), a per-column ray caster
(``render.py``) and a camera with a tilted mount, exposure changes, a stitching seam, blur
and JPEG (``camera.py``). ``make_recording(route, seed)`` returns the first family's
``Recording`` so the benchmark can swap families; ``poses_for`` gives the ground truth
without rendering. Written apart from ``engine.synth`` so loop detection tuned there can be
reported here without tuning on it.
"""

from .camera import Camera
from .recording import IMAGE_CONVENTION, make_recording, poses_for, revisits_for
from .routes import ROUTES

__all__ = ["Camera", "IMAGE_CONVENTION", "ROUTES", "make_recording", "poses_for", "revisits_for"]
