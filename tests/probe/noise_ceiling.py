#!/usr/bin/python3
"""How much of rouen's error on a Blender world's views is the truth's own Monte Carlo noise.

A path tracer's photo carries noise of its own; `rouen validate` scores against it. Render the
same views again with another seed (the nave pipeline's gen.py, which the court, hall and Rouen
worlds run too):

    blender -b -P tests/data/blender_nave/gen.py -- --out /tmp/seed2 --times 4 --no-checks \\
        --only se,street --seed-offset 500 --rouen build/app/rouen

then

    tests/probe/noise_ceiling.py --rouen build/app/rouen --scene SCENE --session SESSION \\
        --slot 4 --data tests/data/blender_nave --second /tmp/seed2

scores each view that has a second render as `rouen validate` does (8-bit, the truth's 99th
green percentile at 230, a linear response: HDR worlds only) and prints: rouen against the
photo, the photo against its second render, the ceiling the photo's noise sets (the two differ
by twice one's noise power: +3.01 dB), the noise's share of rouen's squared error, rouen's own
error with one photo's noise taken out, and rouen against the mean of the two photos; and the
same for the median relative error. Needs numpy and OpenImageIO's Python module.
"""
import argparse, glob, json, math, os, subprocess, sys, tempfile

import numpy as np
import OpenImageIO as oiio

ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
ap.add_argument('--rouen', required=True)
ap.add_argument('--scene', required=True)
ap.add_argument('--session', required=True)
ap.add_argument('--slot', type=int, required=True)
ap.add_argument('--data', required=True, help='the world folder the session was imported from')
ap.add_argument('--second', required=True, help='the folder of the second renders (t<slot>_<name>.exr)')
args = ap.parse_args()

with open(os.path.join(args.scene, 'scene.json')) as f:
    if json.load(f).get('response'):
        sys.exit(f'{args.scene}: the scene has a response curve; this probe scores HDR worlds only')


def read(path):
    buf = oiio.ImageBuf(path)
    if buf.has_error:
        sys.exit(f'{path}: {buf.geterror()}')
    return buf.get_pixels(oiio.FLOAT)[..., :3].astype(np.float64)


with tempfile.TemporaryDirectory() as images:
    r = subprocess.run([args.rouen, 'validate', args.scene, '--session', args.session, '--slot',
                        str(args.slot), '--images', images], capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit(f'rouen validate failed:\n{r.stdout}{r.stderr}')
    views = {}
    for photo in sorted(glob.glob(os.path.join(images, '*_photo.exr'))):
        stem = photo[:-len('_photo.exr')]
        views[os.path.basename(stem)] = (read(photo), read(stem + '_render.exr'),
                                         read(stem + '_difference.exr'))

seconds = sorted(glob.glob(os.path.join(args.second, f't{args.slot}_*.exr')))
if not seconds:
    sys.exit(f'{args.second}: no t{args.slot}_*.exr')
print(f'{"view":38s} {"rouen":>8s} {"photo2":>8s} {"ceiling":>8s} {"noise":>6s} {"own":>8s} {"vs mean":>8s}'
      f'   median: {"rouen":>6s} {"photo2":>6s} {"vs mean":>7s}')
for second in seconds:
    name = os.path.basename(second)[len(f't{args.slot}_'):-len('.exr')]
    original = os.path.join(args.data, os.path.basename(second))
    if name == 'sun' or not os.path.exists(original):
        continue
    a = read(original)
    view = next((v for v, (p, _, _) in views.items()
                 if p.shape == a.shape and np.allclose(p, a, rtol=1e-6, atol=0)), None)
    if view is None:
        print(f'{name}: not among the validated views (a panorama, or another slot)')
        continue
    photo, render, diff = views[view]
    b = read(second)
    mask = ~(diff == 0).all(axis=2)
    high = np.quantile(photo[mask][:, 1], 0.99)
    exposure, floor = 230 / high, 0.01 * high

    def mse(x, y):
        dn = lambda z: np.clip(np.round(np.maximum(z, 0) * exposure), 0, 255)
        return float(((dn(x) - dn(y)) ** 2)[mask].mean())

    def median(x, y):
        return float(np.median((np.abs(x - y) / np.maximum(y, floor))[mask]))

    db = lambda m: 10 * math.log10(255 ** 2 / m) if m > 0 else 99.0
    rouen, photos = mse(render, photo), mse(photo, b)
    noise = photos / 2  # one photo's noise power
    own = rouen - noise
    print(f'{view + " (" + name + ")":38s} {db(rouen):8.2f} {db(photos):8.2f} {db(noise):8.2f} '
          f'{100 * noise / rouen:5.0f}% {db(own) if own > 0 else float("inf"):8.2f} '
          f'{db(mse(render, (photo + b) / 2)):8.2f}   median: {100 * median(render, photo):5.2f}% '
          f'{100 * median(b, photo):5.2f}% {100 * median(render, (photo + b) / 2):6.2f}%')
