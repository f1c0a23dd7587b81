"""Cut the texture crops of ``engine.synth2`` from the real photographs (run once, by hand).

Needs ``/work/shared/data`` (see its README) and the repository's ``tests/data``; the crops are
committed, so neither tests nor CI run this. Boxes are (x0, y0, x1, y1) as fractions of the
source's width and height, read off the equirectangular photos near the horizon (where the
projection barely distorts); every crop is stored at most 512 px wide as JPEG quality 85.
"""

from __future__ import annotations

import sys
from pathlib import Path

import cv2

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[2]
SHARED = Path(sys.argv[1]) if len(sys.argv) > 1 else Path("/work/shared/data")
GOPRO = SHARED / "real" / "panoramax-gopromax"

# name: (source, (x0, y0, x1, y1) in 1/1024 of width and 1/512 of height, what it shows)
CROPS = {
    "station_brick": (GOPRO / "1.jpg", (880, 200, 1024, 330), "brick wall, windows and posters"),
    "station_hall": (GOPRO / "1.jpg", (722, 190, 880, 300), "station front: door, hall, signs"),
    "glass_front": (GOPRO / "1.jpg", (0, 188, 110, 330), "glass shop front with frames"),
    "asphalt": (GOPRO / "1.jpg", (215, 335, 375, 395), "asphalt road surface"),
    "pavement": (GOPRO / "1.jpg", (820, 312, 900, 372), "paved station floor"),
    "canopy": (GOPRO / "1.jpg", (765, 150, 870, 190), "cream canopy underside"),
    "sky": (GOPRO / "1.jpg", (100, 0, 700, 175), "blue sky with clouds"),
    "person": (GOPRO / "1.jpg", (790, 250, 826, 322), "a walking person"),
    "bin": (GOPRO / "1.jpg", (12, 326, 72, 398), "a wheelie bin"),
    "trees": (GOPRO / "3.jpg", (150, 150, 640, 250), "tree line"),
    "bank_stairs": (GOPRO / "3.jpg", (170, 235, 660, 330), "grass bank with stairs"),
    "forest_a": (SHARED / "real" / "pixel3-photosphere.jpg", (0, 95, 512, 290), "forest and ferns"),
    "forest_b": (SHARED / "real" / "pixel3-photosphere.jpg", (512, 95, 1024, 290), "forest and ferns"),
    "dirt_path": (SHARED / "real" / "pixel3-photosphere.jpg", (420, 390, 760, 500), "dirt path"),
    "rock": (REPO / "tests" / "data" / "examplepano_1024.jpg", (0, 300, 1024, 470), "granite rock"),
}


def main() -> None:
    for name, (src, (x0, y0, x1, y1), _what) in CROPS.items():
        img = cv2.imread(str(src))
        h, w = img.shape[:2]
        crop = img[int(y0 / 512 * h):int(y1 / 512 * h), int(x0 / 1024 * w):int(x1 / 1024 * w)]
        scale = min(1.0, 512 / crop.shape[1])
        if scale < 1.0:
            crop = cv2.resize(crop, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
        cv2.imwrite(str(HERE / f"{name}.jpg"), crop, [cv2.IMWRITE_JPEG_QUALITY, 85])


if __name__ == "__main__":
    main()
