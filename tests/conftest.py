import os

# Qt must use the offscreen platform and no OpenGL; set before anything imports Qt.
os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
os.environ.setdefault("QT_OPENGL", "software")
os.environ.setdefault("MPLBACKEND", "Agg")
