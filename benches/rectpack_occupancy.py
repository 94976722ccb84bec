"""Python rectpack's best occupancy on the sizes given as JSON on stdin ([[w, h], ...]), for the
`packing` section of `cargo bench`: every pack algorithm and sort order of rectpack, each on
strips of a few widths around the square root of the total area (rotation on, no padding), the
page height being what the strip used. Prints one JSON object."""

import json
import math
import sys
import time

import rectpack
from rectpack import guillotine, maxrects, skyline

sizes = json.load(sys.stdin)
area = sum(w * h for w, h in sizes)
widest = max(min(w, h) for w, h in sizes)
algorithms = [
    ("MaxRectsBl", maxrects.MaxRectsBl), ("MaxRectsBssf", maxrects.MaxRectsBssf),
    ("MaxRectsBaf", maxrects.MaxRectsBaf), ("MaxRectsBlsf", maxrects.MaxRectsBlsf),
    ("SkylineBl", skyline.SkylineBl), ("SkylineBlWm", skyline.SkylineBlWm),
    ("SkylineMwf", skyline.SkylineMwf), ("SkylineMwfl", skyline.SkylineMwfl),
    ("SkylineMwfWm", skyline.SkylineMwfWm), ("SkylineMwflWm", skyline.SkylineMwflWm),
    ("GuillotineBssfSas", guillotine.GuillotineBssfSas), ("GuillotineBafSas", guillotine.GuillotineBafSas),
    ("GuillotineBlsfSas", guillotine.GuillotineBlsfSas),
]
orders = [("area", rectpack.SORT_AREA), ("perimeter", rectpack.SORT_PERI), ("long side", rectpack.SORT_LSIDE),
          ("short side", rectpack.SORT_SSIDE), ("difference", rectpack.SORT_DIFF), ("ratio", rectpack.SORT_RATIO)]
side = max(widest, math.ceil(math.sqrt(area)))
widths = sorted({max(widest, int(side * factor) // 4 * 4) for factor in (1.0, 1.0625, 1.125, 1.25)})
best = (0.0, None)
started = time.perf_counter()
for name, algorithm in algorithms:
    for order_name, order in orders:
        for width in widths:
            packer = rectpack.newPacker(mode=rectpack.PackingMode.Offline, pack_algo=algorithm,
                                        sort_algo=order, rotation=True)
            packer.add_bin(width, 8 * side)
            for index, (w, h) in enumerate(sizes):
                packer.add_rect(w, h, rid=index)
            packer.pack()
            placed = packer.rect_list()
            if len(placed) != len(sizes):
                continue
            height = max(y + h for _, x, y, w, h, _ in placed)
            occupancy = area / (width * height)
            if occupancy > best[0]:
                best = (occupancy, f"{name}, {order_name}, {width}x{height}")
print(json.dumps({"occupancy": best[0], "variant": best[1], "seconds": time.perf_counter() - started}))
