#!/usr/bin/python3
"""A hostile user's probe of rouen's commands and Python module (issue 30's second probe).

Makes a quick demo (session and scene), then runs every command it can against damaged copies
of them and hostile options, and reports each case that
  - ends on a signal (a crash) or runs past its time limit,
  - prints "internal error" (an exception rouen did not name),
  - fails with an error that does not name the file or option at fault,
  - exits 0 with a NaN or infinity in a JSON or EXR output,
  - changes one of its inputs (the scene, the session), or leaves a temporary behind,
  - (Python) raises something other than a rouen error, TypeError or ValueError.

    tests/probe/hostile.py --rouen build/app/rouen --python build/python \
        --data tests/data/blender_tower --work /tmp/hostile [--parts scene,journal,...]

Parts: scene (scene.json tampered, under render, envmap and report), journal (a journal line
under status), session (session.json under status), options (hostile numbers), outputs (output
paths over inputs, devices and folders), frames (damaged frames and models under status and
solve), kills (solve killed and run again), import (tampered lists, cameras and sites; sky fit),
python (the module). It prints each finding and exits 1 if there is one. Needs numpy and
OpenImageIO's Python module (Debian python3-openimageio) for the EXR check.
"""
import argparse, copy, hashlib, json, os, random, shutil, signal, subprocess, sys, time

ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
ap.add_argument('--rouen', required=True)
ap.add_argument('--python', help='folder of the built module (rouen.cpython-*.so)')
ap.add_argument('--data', required=True, help='a Blender world of tests/data (photos, list, cameras)')
ap.add_argument('--work', required=True)
ap.add_argument('--parts', default='scene,journal,session,options,outputs,frames,kills,import,python')
ap.add_argument('--seed', type=int, default=7)
ap.add_argument('--leaves', type=int, default=140, help='scene.json values tampered (each 4 ways)')
args = ap.parse_args()
R, WORK = os.path.abspath(args.rouen), os.path.abspath(args.work)
PARTS = set(args.parts.split(','))
random.seed(args.seed)
os.makedirs(WORK, exist_ok=True)
findings, ncases = [], 0


def digest(path):
    h = hashlib.sha256()
    if os.path.isfile(path):
        h.update(open(path, 'rb').read())
        return h.hexdigest()
    for root, dirs, files in sorted(os.walk(path)):
        dirs.sort()
        for f in sorted(files):
            if f != 'session.lock':
                p = os.path.join(root, f)
                h.update(p.encode())
                h.update(open(p, 'rb').read())
    return h.hexdigest()


def finite_output(path):
    if path.endswith('.json'):
        try:
            json.load(open(path), parse_constant=lambda c: (_ for _ in ()).throw(ValueError(c)))
        except ValueError:
            return False
    if path.endswith('.exr'):
        import numpy as np
        import OpenImageIO as oiio
        px = oiio.ImageBuf(path).get_pixels(oiio.FLOAT)
        return px is not None and bool(np.isfinite(px).all())
    return True


def run(name, argv, protect=(), outputs=(), names=(), timeout=180):
    """Runs rouen with argv; `names`: an error must contain one of them."""
    global ncases
    ncases += 1
    before = {p: digest(p) for p in protect}
    for o in outputs:
        if os.path.isfile(o):
            os.remove(o)
    try:
        cp = subprocess.run([R] + argv, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        findings.append((name, 'still running after %d s' % timeout, ' '.join(argv)))
        return None
    said = cp.stderr + cp.stdout
    if cp.returncode < 0 or cp.returncode >= 128:
        findings.append((name, 'signal %d' % abs(cp.returncode), said[-300:]))
    if 'internal error' in said:
        findings.append((name, 'internal error', said[-300:]))
    if cp.returncode != 0 and names and not any(n in said for n in names):
        findings.append((name, 'the error names none of %s' % list(names), said[-300:]))
    for p, h in before.items():
        if digest(p) != h:
            findings.append((name, 'input changed: ' + p, ' '.join(argv)))
    if cp.returncode == 0:
        for o in outputs:
            if os.path.isfile(o) and not finite_output(o):
                findings.append((name, 'non-finite values in ' + o, ' '.join(argv)))
        for d in {os.path.dirname(o) for o in outputs}:
            left = [f for f in os.listdir(d) if '.tmp-' in f]
            if left:
                findings.append((name, 'temporaries left: %s' % left, ''))
    return cp


def leaves(j, path=()):
    if isinstance(j, dict):
        for k, v in j.items():
            yield from leaves(v, path + (k,))
    elif isinstance(j, list) and 0 < len(j) <= 8:
        for i, v in enumerate(j):
            yield from leaves(v, path + (i,))
    elif isinstance(j, list) and j:
        yield path  # a long list: replaced whole, and its first element
        yield path + (0,)
    else:
        yield path


def tamper(j, path, value):
    """A copy of j with `path` set to value (or removed: value 'DEL'); None when it cannot be."""
    j = copy.deepcopy(j)
    o = j
    try:
        for k in path[:-1]:
            o = o[k]
        if value == 'DEL':
            del o[path[-1]]
        else:
            o[path[-1]] = value
    except (KeyError, IndexError, TypeError):
        return None
    return j


BAD = [float('nan'), 1e300, -1e300, -1, 0, 2**63, 2.5, '', 'x', [], {}, None, True]


def fresh(src, name):
    dst = os.path.join(WORK, name)
    shutil.rmtree(dst, ignore_errors=True)
    shutil.copytree(src, dst)
    return dst


# The quick demo: a session and its scene (slot 3 held out).
demo = os.path.join(WORK, 'demo')
if not os.path.isfile(os.path.join(demo, 'scene', 'scene.json')):
    shutil.rmtree(demo, ignore_errors=True)
    subprocess.run([R, 'demo', '--quick', '--out', demo], check=True, capture_output=True)
scene0, session0 = os.path.join(demo, 'scene'), os.path.join(demo, 'session')
S = json.load(open(os.path.join(scene0, 'scene.json')))
v0 = sorted(S['views'])[0]
out = os.path.join(WORK, 'out.exr')
LOOK = ['--look-at', '0,0,20', '--from-point', '50,50,2']

if 'scene' in PARTS:
    paths = list(leaves({k: v for k, v in S.items() if k not in ('views', 'atlas', 'timings')}))
    paths += [('views', v0) + p for p in leaves(S['views'][v0])]
    paths += [('environment', 'stereo', 'fit', 'regions', 0) + p
              for p in leaves(S['environment']['stereo']['fit']['regions'][0])]
    paths = list(dict.fromkeys(paths))
    random.shuffle(paths)
    k = 0
    for p in paths[:args.leaves]:
        for v in random.sample(BAD, 3) + ['DEL']:
            j = tamper(S, p, v)
            if j is None:
                continue
            k += 1
            scene = fresh(scene0, 'scene')
            open(os.path.join(scene, 'scene.json'), 'w').write(json.dumps(j))
            cmd = [['render', scene, '--slot', '0', '--out', out],
                   ['render', scene, '--time', '2026-08-25T21:00:00Z', '--out', out, '--size', '64x48'] + LOOK,
                   ['envmap', scene, '--slot', '0', '--out', out, '--width', '64'],
                   ['report', scene, '--out', os.path.join(WORK, 'r.html')]][k % 4]
            run('scene.json %s = %r: %s' % ('/'.join(map(str, p)), v, cmd[0]), cmd, protect=[scene],
                outputs=[out], names=['scene'])

if 'journal' in PARTS or 'session' in PARTS:
    lines = open(os.path.join(session0, 'frames.jsonl')).read().splitlines()
    rec = json.loads(lines[5])
    SJ = json.load(open(os.path.join(session0, 'session.json')))
    todo = []
    if 'journal' in PARTS:
        todo += [('journal', p) for p in dict.fromkeys(leaves(rec))]
    if 'session' in PARTS:
        todo += [('session', p) for p in list(dict.fromkeys(leaves(SJ)))[:60]]
    for what, p in todo:
        for v in random.sample(BAD, 3) + ['DEL']:
            j = tamper(rec if what == 'journal' else SJ, p, v)
            if j is None:
                continue
            session = fresh(session0, 'session')
            if what == 'journal':
                L = list(lines)
                L[5] = json.dumps(j)
                open(os.path.join(session, 'frames.jsonl'), 'w').write('\n'.join(L) + '\n')
            else:
                open(os.path.join(session, 'session.json'), 'w').write(json.dumps(j))
            run('%s %s = %r: status' % (what, '/'.join(map(str, p)), v), ['status', session])

if 'options' in PARTS:
    scene = fresh(scene0, 'scene')
    NUM = ['nan', 'inf', '-1', '0', '1e308', '99999999999', '1,2', '', '25:00', '1e-300']
    opts = [
        (['render', scene, '--out', out, '--size', '32x24'] + LOOK,
         ['--fov', '--pbs', '--time', '--overcast-brightness', '--look-at']),
        (['render', scene, '--out', out] + LOOK, ['--size']),
        (['render', scene, '--out', out, '--png', os.path.join(WORK, 'o.png'), '--view', v0], ['--slot', '--exposure']),
        (['render', scene, '--out', os.path.join(WORK, 'seq'), '--from', '2026-08-25T18:00:00Z', '--to',
          '2026-08-25T18:10:00Z', '--size', '16x12'] + LOOK, ['--step']),
        (['envmap', scene, '--out', out], ['--slot', '--width', '--height', '--pbs', '--time']),
        (['timelapse', scene, '--out', os.path.join(WORK, 'tl'), '--date', '2026-08-25', '--size', '16x12',
          '--from', '10:00', '--to', '10:30'] + LOOK, ['--step', '--tz']),
        (['sun'], ['--lat', '--lon', '--height', '--time']),
        (['validate', scene, '--session', session0], ['--slot', '--exclude-block']),
    ]
    for base, names in opts:
        for o in names:
            for v in NUM:
                run('%s %s %s' % (base[0], o, v), base + [o, v], protect=[scene, session0], outputs=[out])

if 'outputs' in PARTS:
    scene = fresh(scene0, 'scene')
    frame = os.path.join(session0, 'frames', sorted(os.listdir(os.path.join(session0, 'frames')))[3])
    targets = [os.path.join(scene, 'scene.json'), os.path.join(scene, 'albedo_se.exr'), frame, scene, session0,
               '/dev/null', '/dev/full', os.path.join(WORK, 'nodir', 'x.exr'), os.path.join(WORK, 'x.exr') + '/',
               '/proc/self/x.exr', os.path.join(scene, 'atlas', 'x.exr'), os.path.join(session0, 'x.exr'), '']
    for t in targets:
        for base in (['render', scene, '--slot', '0', '--out'], ['envmap', scene, '--slot', '0', '--width', '32', '--out'],
                     ['report', scene, '--out'], ['export', scene, '--gltf'],
                     ['validate', scene, '--session', session0, '--slot', '0', '--json']):
            run('%s output %s' % (base[0], t), base + [t], protect=[scene, session0])

if 'frames' in PARTS:
    frames = sorted(os.listdir(os.path.join(session0, 'frames')))
    damages = ['half', 'ten bytes', 'empty', 'bit flips', 'a folder', 'noise', 'a wrong magic number', 'a link out']
    for i in range(60):
        session = fresh(session0, 'session')
        f = random.choice(frames)
        p = os.path.join(session, 'frames', f)
        d = damages[i % len(damages)]
        data = open(p, 'rb').read()
        if d == 'half':
            open(p, 'wb').write(data[:len(data) // 2])
        elif d == 'ten bytes':
            open(p, 'wb').write(data[:10])
        elif d == 'empty':
            open(p, 'wb').write(b'')
        elif d == 'bit flips':
            b = bytearray(data)
            for _ in range(20):
                b[random.randrange(len(b))] ^= 1 << random.randrange(8)
            open(p, 'wb').write(bytes(b))
        elif d == 'a folder':
            os.remove(p)
            os.mkdir(p)
        elif d == 'noise':
            open(p, 'wb').write(os.urandom(len(data)))
        elif d == 'a wrong magic number':
            open(p, 'wb').write(b'\xff\xd8\xff\xe0' + data[4:])
        else:
            os.remove(p)
            os.symlink('/etc/passwd', p)
        run('frame %s made %s: status' % (f, d), ['status', session])
        if i % 6 == 0:
            so = os.path.join(WORK, 'scene_f')
            shutil.rmtree(so, ignore_errors=True)
            cp = run('frame %s made %s: solve' % (f, d), ['solve', session, '--out', so, '--holdout-slot', '3'],
                     names=[f], timeout=600)
            if cp is not None and cp.returncode == 0:
                findings.append(('frame %s made %s' % (f, d), 'solved all the same', ''))
    obj = open(os.path.join(session0, 'model.obj')).read().splitlines()
    for i in range(40):
        session = fresh(session0, 'session')
        L = list(obj)
        k = random.randrange(len(L))
        kind = ['a vertex at 1e300', 'an index past the end', 'a NaN vertex', 'cut short', 'a 5000-letter group'][i % 5]
        if kind == 'a vertex at 1e300':
            L[k] = 'v 1e300 0 0'
        elif kind == 'an index past the end':
            L[k] = 'f 999999 1 2'
        elif kind == 'a NaN vertex':
            L[k] = 'v nan nan nan'
        elif kind == 'cut short':
            L = L[:k]
        else:
            L[k] = 'g ' + 'x' * 5000
        open(os.path.join(session, 'model.obj'), 'w').write('\n'.join(L) + '\n')
        run('model line %d: %s: status' % (k + 1, kind), ['status', session])
        if i % 8 == 0:
            so = os.path.join(WORK, 'scene_m')
            shutil.rmtree(so, ignore_errors=True)
            run('model line %d: %s: solve' % (k + 1, kind), ['solve', session, '--out', so, '--holdout-slot', '3'],
                names=['model.obj'], timeout=600)

if 'kills' in PARTS:
    session = fresh(session0, 'session')
    so = os.path.join(WORK, 'scene_k')
    for i in range(8):
        shutil.rmtree(so, ignore_errors=True)
        pr = subprocess.Popen([R, 'solve', session, '--out', so, '--holdout-slot', '3'],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        time.sleep(random.uniform(0.5, 12))
        sig = [signal.SIGTERM, signal.SIGKILL, signal.SIGINT][i % 3]
        pr.send_signal(sig)
        pr.wait()
        ncases += 1
        if os.path.isfile(os.path.join(so, 'scene.json')):
            cp = run('render after a solve killed by %s' % sig.name, ['render', so, '--slot', '0', '--out', out])
            if cp is not None and cp.returncode != 0:
                findings.append(('solve killed by %s' % sig.name, 'left a scene.json that does not render',
                                 cp.stderr[-300:]))
        cp = run('solve again after %s' % sig.name, ['solve', session, '--out', so, '--holdout-slot', '3'], timeout=600)
        if cp is not None and cp.returncode != 0:
            findings.append(('solve again after %s' % sig.name, 'does not finish', cp.stderr[-300:]))

if 'import' in PARTS:
    D = os.path.abspath(args.data)
    photos = fresh(D, 'photos')
    lines = open(os.path.join(D, 'list.txt')).read().splitlines()
    cams = json.load(open(os.path.join(D, 'cameras.json')))
    truth = json.load(open(os.path.join(D, 'truth.json')))
    site = '%(lat_deg)s,%(lon_deg)s,%(height_m)s' % truth['site']
    so = os.path.join(WORK, 'imported')
    TOK = ['nan', '-1', '0', '1e308', '1/0', '0/0', '2026-13-45T99:00:00Z', 'group=', 'group=a=b', 'target=roof',
           'nd=-3', 'nd=nan', 'nd=1,2', '../../etc/passwd', '/etc/passwd', '#', 'x' * 3000,
           'target=sun target=sky', 'nd=1e308', '1/250', '-', '2026-10-02T03:00:00Z', '2026-10-02T07:00:00+25:00']
    lp = os.path.join(WORK, 'list.txt')

    def imported(name, argv, names):
        shutil.rmtree(so, ignore_errors=True)
        cp = run(name, ['import', '--photos', photos, '--site=' + site, '--out', so] + argv, names=names)
        if cp is not None and cp.returncode != 0:
            left = [f for f in os.listdir(WORK) if f.startswith('imported')]
            if left:
                findings.append((name, 'a failed import left %s' % left, ''))

    for i in range(120):
        L = list(lines)
        k = random.randrange(1, len(L))
        w = L[k].split()
        j = random.randrange(len(w) + 1)
        t = random.choice(TOK)
        w[j:j + 1] = [t]
        L[k] = ' '.join(w)
        open(lp, 'w').write('\n'.join(L) + '\n')
        imported('list line %d word %d = %s' % (k + 1, j + 1, t[:30]),
                 ['--list', lp, '--cameras', os.path.join(photos, 'cameras.json'), '--model',
                  os.path.join(photos, 'building.obj'), '--sky-mask', 'auto'], names=['list.txt', '.exr'])
    cp_ = os.path.join(WORK, 'cams.json')
    cpaths = list(leaves(cams))
    random.shuffle(cpaths)
    for p in cpaths[:80]:
        v = random.choice(BAD)
        open(cp_, 'w').write(json.dumps(tamper(cams, p, v)))
        imported('cameras %s = %r' % ('/'.join(map(str, p)), v),
                 ['--list', os.path.join(photos, 'list.txt'), '--cameras', cp_], names=['cams.json'])
    for s in ['nan,0,0', '91,0,0', '0,181,0', '0,0,1e300', '0,0', '0,0,0,0', ',,', '1e-320,0,0', '43.77,11.25,-600']:
        shutil.rmtree(so, ignore_errors=True)
        run('site %s' % s, ['import', '--photos', photos, '--list', os.path.join(photos, 'list.txt'),
                            '--site=' + s, '--out', so], names=['--site'])
    pano = sorted(f for f in os.listdir(D) if f.endswith('_pano.exr'))[0]
    for what, a in [('a missing image', ['--image', os.path.join(WORK, 'none.exr')]), ('a folder', ['--image', WORK]),
                    ('a text', ['--image', os.path.join(D, 'list.txt')]),
                    ('samples of another file', ['--samples', os.path.join(D, 'list.txt')]),
                    ('a mask of another size', ['--image', os.path.join(D, pano), '--mask', os.path.join(D, 'README.md')]),
                    ('1e8 samples', ['--image', os.path.join(D, pano), '--max-samples', '100000000'])]:
        for sun in (['120', '20'], ['nan', '95'], ['1e308', '-5']):
            run('sky fit, %s, sun %s' % (what, sun), ['sky', 'fit'] + a + ['--sun-azimuth', sun[0], '--sun-elevation',
                                                                        sun[1], '--out', os.path.join(WORK, 'fit.json')],
                outputs=[os.path.join(WORK, 'fit.json')])

if 'python' in PARTS and args.python:
    scene, session = scene0, session0
    cases = []
    for p in [scene, session, '', '/', '/dev/null', '/etc/passwd', WORK + '/none', 'x' * 5000, 'a\x00b']:
        cases += ['rouen.Scene(%r).views' % p, 'rouen.Session(%r).status()' % p, 'rouen.read_image(%r)' % p]
    for p in [123, None, 1.5, [scene], b'/nonexistent', {'a': 1}]:
        cases += ['rouen.Scene(%r)' % (p,), 'rouen.Session(%r)' % (p,), 'rouen.read_image(%r)' % (p,)]
    for t in ['"2026-08-25T21:00:00Z"', '"nonsense"', '"2026-08-25T05:00:00Z"', '""', '123', 'float("nan")',
              '"9999-12-31T23:59:59Z"', '"2026-08-25T21:00:00+99:00"']:
        cases.append('a = rouen.Scene(%r).render(time=%s); assert a.size and (a == a).all()' % (scene, t))
    for s in ['-1', '0', '99', '2**40', '1.5', '"0"', 'None']:
        cases.append('a = rouen.Scene(%r).render(slot=%s); assert (a == a).all()' % (scene, s))
    for v in ['"%s"' % v0, '"nope"', '"../../etc"', '""', '5']:
        cases.append('a = rouen.Scene(%r).render(slot=0, view=%s); assert (a == a).all()' % (scene, v))
    for pbs in ['-1', '2', 'float("nan")', 'float("inf")', '0.5']:
        cases.append('a = rouen.Scene(%r).render(time="2026-08-25T21:00:00Z", pbs=%s); assert (a == a).all()' % (scene, pbs))
    for pw in ['[-1]', '[99]', '[0, 1, 2, 3, 4]', '[2**40]']:
        cases.append('rouen.Scene(%r).render(time="2026-08-25T21:00:00Z", predict_without_slots=%s)' % (scene, pw))
    for sl in ['-1', '99', '2**40', '3']:
        cases.append('rouen.Scene(%r).validate(%r, %s)' % (scene, session, sl))
    cases += ['rouen.Scene(%r).validate(%r, 3, erode_px=%s)' % (scene, session, e) for e in ('-5', '10**6')]
    cases.append('rouen.Scene(%r).validate(%r, 3, exclude_blocks=["nope"])' % (scene, session))
    po = os.path.join(WORK, 'pyscene')
    for cfg in ['{"grid": {"spacing_m": float("nan")}}', '{"grid": {"spacing_m": -1}}', '{"nope": 1}', '{"grid": 5}',
                '{"hemisphere": {"directions": 2**70}}', '{"hemisphere": {"directions": 2.5}}', '"/etc/passwd"', '5',
                '{"albedo": {"bounces": -1}}', '{"grid": {"spacing_m": 1e-9}}']:
        cases.append('import shutil; shutil.rmtree(%r, ignore_errors=True); rouen.solve(%r, %r, holdout_slots=[3], '
                     'config=%s)' % (po, session, po, cfg))
    for hs in ['[-1]', '[99]', '[0,1,2,3,4]', '[2**40]']:
        cases.append('import shutil; shutil.rmtree(%r, ignore_errors=True); rouen.solve(%r, %r, holdout_slots=%s)'
                     % (po, session, po, hs))
    for o in [scene, session, os.path.join(session, 'x'), '/dev/null', '']:
        cases.append('rouen.solve(%r, %r, holdout_slots=[3])' % (session, o))
    cases.append('rouen.solve(%r, %r, holdout_slots=[3], log=5)' % (session, po + '1'))
    cases.append('rouen.solve(%r, %r, holdout_slots=[3], log=lambda s: 1/0)' % (session, po + '2'))
    cases.append('rouen.solve(%r, %r, holdout_slots=[3], cancel=5)' % (session, po + '3'))
    for c in cases:
        ncases += 1
        code = ('import sys; sys.path.insert(0, %r); import rouen\ntry:\n    %s\n'
                'except (rouen.Error, rouen.Cancelled, TypeError, ValueError, AssertionError, ZeroDivisionError) as e:\n'
                '    print("raised", type(e).__name__, str(e)[:200])\n' % (os.path.abspath(args.python), c))
        try:
            cp = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, timeout=300)
        except subprocess.TimeoutExpired:
            findings.append((c, 'still running after 300 s', ''))
            continue
        said = cp.stdout + cp.stderr
        if cp.returncode < 0:
            findings.append((c, 'signal %d' % -cp.returncode, said[-300:]))
        elif cp.returncode != 0:
            findings.append((c, 'an exception rouen does not name', said[-300:]))
        elif 'raised AssertionError' in said:
            findings.append((c, 'an image with NaN or no pixel', said[-300:]))
        elif 'internal error' in said:
            findings.append((c, 'internal error', said[-300:]))

print('%d cases, %d findings' % (ncases, len(findings)))
for name, what, detail in findings:
    print('%s | %s | %s' % (name[:200], what, detail.replace('\n', ' ')[:300]))
sys.exit(1 if findings else 0)
