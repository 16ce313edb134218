#!/usr/bin/env python3
"""Independent forward kinematics for ASF/AMC and BVH, used to check the Rust FK.

Written separately from the Rust code (own parsers, rotations built from axis-angle via
Rodrigues' formula, quaternion-free), standard library only, so it runs on a bare Debian with
python3. Prints CSV `frame,joint,x,y,z` (frames from 0, joints in file order: ASF root then
bone ends in :bonedata order; BVH joints and End Sites as <parent>_End in file order).

Usage: fk_reference.py SKELETON.asf MOTION.amc      or      fk_reference.py MOTION.bvh
"""
import math
import sys


def rodrigues(axis, deg):
    """Rotation matrix about unit axis (tuple) by deg degrees, as nested lists."""
    x, y, z = axis
    t = math.radians(deg)
    c, s, C = math.cos(t), math.sin(t), 1.0 - math.cos(t)
    return [[c + x * x * C, x * y * C - z * s, x * z * C + y * s],
            [y * x * C + z * s, c + y * y * C, y * z * C - x * s],
            [z * x * C - y * s, z * y * C + x * s, c + z * z * C]]


AXES = {'x': (1.0, 0.0, 0.0), 'y': (0.0, 1.0, 0.0), 'z': (0.0, 0.0, 1.0)}


def matmul(a, b):
    return [[sum(a[i][k] * b[k][j] for k in range(3)) for j in range(3)] for i in range(3)]


def apply(m, v):
    return [sum(m[i][k] * v[k] for k in range(3)) for i in range(3)]


def transpose(m):
    return [[m[j][i] for j in range(3)] for i in range(3)]


EYE = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]


def fixed_axes(letters, angles):
    """Rotations about fixed axes, first listed applied first."""
    r = EYE
    for a, v in zip(letters, angles):
        r = matmul(rodrigues(AXES[a], v), r)
    return r


def read_lines(path):
    with open(path, 'rb') as f:
        data = f.read().decode('latin-1')
    return data.replace('\r\n', '\n').replace('\r', '\n').split('\n')


def asf_amc(asf_path, amc_path):
    lines = read_lines(asf_path)
    section = None
    root = {'order': [], 'axis': 'xyz', 'position': [0, 0, 0], 'orientation': [0, 0, 0]}
    bones, cur, limits_mode = [], None, False
    parent = {}
    for raw in lines:
        s = raw.strip()
        if not s or s.startswith('#'):
            continue
        tok = s.split()
        if tok[0].startswith(':'):
            section = tok[0][1:].lower()
            continue
        if section == 'root':
            if tok[0] == 'order':
                root['order'] = [t.lower() for t in tok[1:]]
            elif tok[0] == 'axis':
                root['axis'] = tok[1].lower()
            elif tok[0] in ('position', 'orientation'):
                root[tok[0]] = [float(t) for t in tok[1:4]]
        elif section == 'bonedata':
            if tok[0] == 'begin':
                cur = {'dof': [], 'axis': [0, 0, 0], 'order': 'xyz'}
            elif tok[0] == 'end':
                bones.append(cur)
                cur = None
            elif tok[0] == 'name':
                cur['name'] = tok[1]
            elif tok[0] == 'direction':
                cur['dir'] = [float(t) for t in tok[1:4]]
            elif tok[0] == 'length':
                cur['len'] = float(tok[1])
            elif tok[0] == 'axis':
                cur['axis'] = [float(t) for t in tok[1:4]]
                cur['order'] = tok[4].lower()
            elif tok[0] == 'dof':
                cur['dof'] = [t.lower() for t in tok[1:]]
        elif section == 'hierarchy':
            if tok[0] in ('begin', 'end'):
                continue
            for child in tok[1:]:
                parent[child] = tok[0]
    by_name = {b['name']: b for b in bones}
    frames = []
    cur_frame = None
    for raw in read_lines(amc_path):
        s = raw.strip()
        if not s or s.startswith('#') or s.startswith(':'):
            continue
        tok = s.split()
        if len(tok) == 1 and tok[0].isdigit():
            cur_frame = {}
            frames.append(cur_frame)
            continue
        cur_frame[tok[0]] = [float(t) for t in tok[1:]]
    out = []
    for fi, fr in enumerate(frames):
        vals = fr['root']
        t = [0.0, 0.0, 0.0]
        rl, ra = [], []
        for ch, v in zip(root['order'], vals):
            if ch[0] == 't':
                t['xyz'.index(ch[1])] = v
            else:
                rl.append(ch[1])
                ra.append(v)
        rot = {'root': matmul(fixed_axes(root['axis'], root['orientation']), fixed_axes(rl, ra))}
        end = {'root': [root['position'][i] + t[i] for i in range(3)]}
        out.append((fi, 'root', end['root']))
        pending = list(bones)
        while pending:
            rest = []
            for b in pending:
                p = parent[b['name']]
                if p not in end:
                    rest.append(b)
                    continue
                C = fixed_axes(b['order'], b['axis'])
                dv = fr.get(b['name'], [])
                M = fixed_axes([d[1] for d in b['dof']], dv)
                R = matmul(rot[p], matmul(C, matmul(M, transpose(C))))
                v = [b['dir'][i] * b['len'] for i in range(3)]
                e = apply(R, v)
                rot[b['name']] = R
                end[b['name']] = [end[p][i] + e[i] for i in range(3)]
            pending = rest
        for b in bones:
            out.append((fi, b['name'], end[b['name']]))
    return out


def bvh(path):
    lines = read_lines(path)
    toks = []
    k = 0
    while k < len(lines) and lines[k].strip() != 'MOTION':
        toks.extend(lines[k].split())
        k += 1
    joints = []  # (name, parent, offset, channels)
    stack = []
    i = 0
    last = None
    while i < len(toks):
        t = toks[i]
        if t in ('ROOT', 'JOINT'):
            joints.append([toks[i + 1], stack[-1] if stack else None, None, []])
            last = len(joints) - 1
            i += 2
        elif t == 'End':
            joints.append([joints[stack[-1]][0] + '_End', stack[-1], None, []])
            last = len(joints) - 1
            i += 2
        elif t == '{':
            stack.append(last)
            i += 1
        elif t == '}':
            stack.pop()
            i += 1
        elif t == 'OFFSET':
            joints[stack[-1]][2] = [float(x) for x in toks[i + 1:i + 4]]
            i += 4
        elif t == 'CHANNELS':
            n = int(toks[i + 1])
            joints[stack[-1]][3] = toks[i + 2:i + 2 + n]
            i += 2 + n
        else:
            i += 1
    rows = [l.split() for l in lines[k + 3:] if l.strip()]
    out = []
    for fi, row in enumerate(rows):
        vals = [float(x) for x in row]
        c = 0
        wr, wp = [], []
        for name, par, off, chans in joints:
            R = EYE
            t = list(off)
            for ch in chans:
                v = vals[c]
                c += 1
                ax = ch[0].lower()
                if ch[1:].lower() == 'position':
                    t['xyz'.index(ax)] += v
                else:
                    R = matmul(R, rodrigues(AXES[ax], v))
            if par is None:
                wp.append(t)
                wr.append(R)
            else:
                d = apply(wr[par], t)
                wp.append([wp[par][j] + d[j] for j in range(3)])
                wr.append(matmul(wr[par], R))
            out.append((fi, name, wp[-1]))
    return out


def main():
    args = sys.argv[1:]
    rows = bvh(args[0]) if len(args) == 1 else asf_amc(args[0], args[1])
    w = sys.stdout.write
    w('frame,joint,x,y,z\n')
    for f, n, p in rows:
        w('%d,%s,%.10f,%.10f,%.10f\n' % (f, n, p[0], p[1], p[2]))


if __name__ == '__main__':
    main()
