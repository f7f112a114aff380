#!/usr/bin/env python3
"""Writes the `import csv` CLI fixtures (committed; rerun to remake them, they are deterministic).

A robot with B = 0.3 m and 4096-tick encoders on 5 cm wheels drives a line of 2 m, a turn on the
spot of +90 deg and a line of 1 m at 0.4 m/s, logged at 20 Hz. The reference is a motion-capture
pose in its own world frame (origin (3.2, -1.7), rotated by 2.5 rad), theta wrapped to (-pi, pi]:
- lab/run-01.csv, lab/run-02.csv: wheels in ticks (import with --left-scale/--right-scale
  2*pi*0.05/4096); run-02 has the reference only every 4th row and starts 10 ms after the wheels;
- mm/run-01.csv: wheels in millimetres (import without scales must be refused).
"""
import math
import os

B, R_WHEEL, TICKS = 0.3, 0.05, 4096
M_PER_TICK = 2 * math.pi * R_WHEEL / TICKS
WORLD = (3.2, -1.7, 2.5)
V, RATE = 0.4, 20.0

# keyframes (t, L, R)
kf = [(0.0, 0.0, 0.0)]
def add(dl, dr):
    t, l, r = kf[-1]
    kf.append((t + max(abs(dl), abs(dr)) / V, l + dl, r + dr))
add(2.0, 2.0)
a = math.pi / 2
add(-a * B / 2, a * B / 2)
add(1.0, 1.0)

def wheels(t):
    for (t0, l0, r0), (t1, l1, r1) in zip(kf, kf[1:]):
        if t <= t1:
            f = (t - t0) / (t1 - t0)
            return l0 + f * (l1 - l0), r0 + f * (r1 - r0)
    return kf[-1][1:]

def pose(t):
    """Exact arc integration of the wheel travel up to t (start frame)."""
    x = y = th = 0.0
    times = [k[0] for k in kf if k[0] < t] + [t]
    for ta, tb in zip(times, times[1:]):
        la, ra = wheels(ta)
        lb, rb = wheels(tb)
        d, da = ((lb - la) + (rb - ra)) / 2, ((rb - ra) - (lb - la)) / B
        if abs(da) < 1e-12:
            dx, dy = d, 0.0
        else:
            dx, dy = d * math.sin(da) / da, d * (1 - math.cos(da)) / da
        x, y = x + math.cos(th) * dx - math.sin(th) * dy, y + math.sin(th) * dx + math.cos(th) * dy
        th += da
    return x, y, th

def world(p):
    c, s = math.cos(WORLD[2]), math.sin(WORLD[2])
    th = math.remainder(WORLD[2] + p[2], 2 * math.pi)
    return WORLD[0] + c * p[0] - s * p[1], WORLD[1] + s * p[0] + c * p[1], th

def write(path, unit, every=1, ref_offset=0.0):
    """Wheel rows at 20 Hz. Without ref_offset the reference sits on every `every`-th wheel row
    and the last; with it, the reference is on rows of its own, ref_offset after every
    `every`-th wheel row."""
    os.makedirs(os.path.dirname(path), exist_ok=True)
    t_end = kf[-1][0]
    n = int(math.floor(t_end * RATE + 1e-9))
    with open(path, "w") as f:
        f.write("t,left,right,x,y,theta\n")
        for k in range(n + 1):
            t = k / RATE
            l, r = wheels(t)
            on_row = not ref_offset and (k % every == 0 or k == n)
            cells = ",%.9f,%.9f,%.9f" % world(pose(t)) if on_row else ",,,"
            f.write(f"{t:.3f},{l / unit:.6f},{r / unit:.6f}{cells}\n")
            if ref_offset and k % every == 0 and k < n:
                tr = t + ref_offset
                f.write(f"{tr:.3f},,,%.9f,%.9f,%.9f\n" % world(pose(tr)))

here = os.path.dirname(os.path.abspath(__file__))
write(os.path.join(here, "lab", "run-01.csv"), M_PER_TICK)
write(os.path.join(here, "lab", "run-02.csv"), M_PER_TICK, every=4, ref_offset=0.01)
write(os.path.join(here, "mm", "run-01.csv"), 1e-3)
