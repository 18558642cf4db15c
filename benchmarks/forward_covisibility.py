"""Which frames of a forward sequence see each other: stock COLMAP's verified matches
(default SIFT, exhaustive matching and verification, as the `colmap` peer) between frames
`gap` apart, beside what the pose-only co-visibility rule says
(`bench.evaluation.truth.covisible_pairs`, a model without points).

    .venv/bin/python benchmarks/forward_covisibility.py ../shared/datasets/kitti-seq2 \
        --anchors 0,10,20,30,40 --gaps 1,2,3,4,5,6,8,10,15
"""

import argparse
import tempfile
from pathlib import Path

import numpy as np
import pycolmap

from bench.backend.peers import extract, write_extracted
from bench.backend.reconstruction import quiet_colmap, write_images
from bench.evaluation.relative import MIN_SHARED
from bench.evaluation.truth import covisible_pairs
from bench.frontend.colmap_model import read_model
from bench.frontend.views import Source

ap = argparse.ArgumentParser(
    description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
)
ap.add_argument("dataset", type=Path)
ap.add_argument("--anchors", default="0,10,20,30,40")
ap.add_argument("--gaps", default="1,2,3,4,5,6,8,10,15")
a = ap.parse_args()
src = Source.of(a.dataset)
model = read_model(src.model)
names, cams = [n for n, _ in model], [c for _, c in model]
rule = set(covisible_pairs(cams, None, MIN_SHARED)[0])
anchors = [int(x) for x in a.anchors.split(",")]
gaps = [int(x) for x in a.gaps.split(",")]
work = Path(tempfile.mkdtemp(prefix="forward-"))
sift = extract(src.images, names, cams, 0, work / "sift")
print(f"{'gap':>4} {'rule':>5}  verified matches per anchor ({', '.join(map(str, anchors))})")
for gap in gaps:
    counts = []
    for i in anchors:
        j = i + gap
        if j >= len(names):
            continue
        db_path = work / f"{i}-{j}.db"
        db = pycolmap.Database.open(str(db_path))
        write_images(db, [cams[i], cams[j]], [names[i], names[j]])
        write_extracted(db, [cams[i], cams[j]], [sift[i], sift[j]])
        db.close()
        options = pycolmap.FeatureMatchingOptions()
        options.num_threads = 1
        with quiet_colmap():
            pycolmap.match_exhaustive(db_path, matching_options=options, device=pycolmap.Device.cpu)
        db = pycolmap.Database.open(str(db_path))
        counts.append(db.num_inlier_matches())
        db.close()
    covisible = np.mean([(i, i + gap) in rule for i in anchors if i + gap < len(names)])
    print(f"{gap:>4} {covisible:>5.2f}  {counts}")
