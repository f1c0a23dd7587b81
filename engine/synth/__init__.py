"""Synthetic 360-degree worlds and recordings: the project's own test, demo and benchmark data.

``make_recording(route, look, seed)`` renders a route (see ``ROUTES``) in a world (see
``LOOKS``) to equirectangular frames with ground-truth poses; ``write_recording`` writes it
as a video, ROS1/ROS2 bags, an image folder and a poses CSV.
"""

from .recording import FORMATS, Recording, make_recording, write_recording
from .render import render
from .routes import ROUTES, Route, make_route
from .world import LOOKS, World, build_world

__all__ = ["FORMATS", "LOOKS", "ROUTES", "Recording", "Route", "World", "build_world",
           "make_recording", "make_route", "render", "write_recording"]
