"""What a street's motion masks must find and must leave (``synth-street --movers``), in metres:

  * a car and a cyclist riding ahead of the training camera at its own speed, in its lane: they
    stay put in the image while the road beneath them flows (the hard case for masks from a
    reference's residual: the reference renders them as something far away);
  * pedestrians crossing the road, back and forth;
  * parked cars half on the sidewalk: static, so not transient (their material is ``PARKED_CAR``).

Everything is drawn from a generator of its own, so the street without movers stays as it was.
"""

from __future__ import annotations

import random
from dataclasses import dataclass

import torch
from torch import Tensor

from nerf2gs_plugin.data.synthetic.layout import (
    CAR_BODY, CAR_CABIN, CAR_WHEELS, CROSSWALKS, PARKED_CAR, POLE, ROAD_HALF, STREET_HALF_LEN, TRUNK, Boxes, StreetLayout, empty_boxes,
)

LEAD_CAR_GAP = 13.0  # metres ahead of the camera, in its lane
CYCLIST_GAP = 7.0  # metres ahead, near the right kerb
PEDESTRIAN_SPAN = 7.5  # they walk across |y| < this (sidewalk to sidewalk)


@dataclass
class Pedestrian:
    x: float
    phase: float  # metres along the back-and-forth walk at t = 0
    speed: float
    colour: tuple[float, float, float]


@dataclass
class Movers:
    pedestrians: list[Pedestrian]
    lead_colour: tuple[float, float, float]
    cyclist_colour: tuple[float, float, float]
    parked: Boxes

    def boxes(self, t: float, c2w: Tensor) -> Boxes:
        """The movers at time ``t`` for the training camera ``c2w [3, 4]`` (the lead car and the
        cyclist are placed ahead of it along its heading, at the lane's centre and kerb)."""
        x0 = float(c2w[0, 3])
        d = 1.0 if float(-c2w[0, 2]) >= 0 else -1.0  # OpenGL: the camera looks along -z
        lane = -d * ROAD_HALF / 2  # right-hand traffic, as the training drive
        rows = _car_rows(x0 + d * LEAD_CAR_GAP, lane, d, self.lead_colour, (CAR_BODY, CAR_CABIN, CAR_WHEELS))
        cx, cy = x0 + d * CYCLIST_GAP, -d * (ROAD_HALF - 0.6)
        rows.append(((cx - 0.85, cy - 0.08, 0.0), (cx + 0.85, cy + 0.08, 0.95), CAR_WHEELS, (0.08, 0.08, 0.09)))  # the bike
        rows.append(((cx - 0.3, cy - 0.25, 0.95), (cx + 0.3, cy + 0.25, 1.6), CAR_BODY, self.cyclist_colour))  # the rider
        rows.append(((cx - 0.12, cy - 0.12, 1.6), (cx + 0.12, cy + 0.12, 1.85), CAR_WHEELS, (0.75, 0.6, 0.5)))  # the head
        span = 2 * PEDESTRIAN_SPAN
        for p in self.pedestrians:
            s = (p.phase + p.speed * t) % (2 * span)
            y = -PEDESTRIAN_SPAN + (s if s < span else 2 * span - s)
            rows.append(((p.x - 0.22, y - 0.25, 0.0), (p.x + 0.22, y + 0.25, 1.5), CAR_BODY, p.colour))
            rows.append(((p.x - 0.11, y - 0.11, 1.5), (p.x + 0.11, y + 0.11, 1.75), CAR_WHEELS, (0.75, 0.6, 0.5)))
        b = Boxes.build(rows)
        b.ident = b.ident + 20_000
        return b


def _car_rows(x: float, y: float, d: float, colour, materials: tuple[int, int, int]) -> list:
    body, cabin, wheels = materials
    glass = tuple(0.10 + 0.2 * v for v in colour)
    cab_lo, cab_hi = (x - 1.25, x + 0.85) if d > 0 else (x - 0.85, x + 1.25)
    return [((x - 2.15, y - 0.9, 0.28), (x + 2.15, y + 0.9, 1.05), body, colour),
            ((cab_lo, y - 0.8, 1.05), (cab_hi, y + 0.8, 1.55), cabin, glass),
            ((x - 1.75, y - 0.82, 0.0), (x + 1.75, y + 0.82, 0.28), wheels, (0.05, 0.05, 0.05))]


def build_movers(layout: StreetLayout, num_pedestrians: int = 4, num_parked: int = 4) -> Movers:
    """Pedestrians at the crosswalks and between them, parked cars clear of the poles and trees."""
    rng = random.Random(layout.seed * 104729 + 3)
    cols = [(0.80, 0.15, 0.20), (0.15, 0.35, 0.75), (0.95, 0.80, 0.15), (0.30, 0.60, 0.30), (0.60, 0.30, 0.65), (0.95, 0.50, 0.10)]
    xs = list(CROSSWALKS) + [rng.uniform(-20.0, 20.0) for _ in range(max(0, num_pedestrians - len(CROSSWALKS)))]
    peds = [Pedestrian(xs[i] + rng.uniform(-1.0, 1.0), rng.uniform(0.0, 4 * PEDESTRIAN_SPAN), rng.uniform(1.1, 1.6),
                       cols[rng.randrange(len(cols))]) for i in range(num_pedestrians)]
    furniture = [(float(lo[0] + hi[0]) / 2, float(lo[1] + hi[1]) / 2) for lo, hi, m in
                 zip(layout.static.lo, layout.static.hi, layout.static.material.tolist()) if m in (POLE, TRUNK)]
    rows: list = []
    tries = 0
    while len(rows) < 3 * num_parked and tries < 200:
        tries += 1
        side = rng.choice((-1.0, 1.0))
        x, y = rng.uniform(-STREET_HALF_LEN + 6, STREET_HALF_LEN - 6), side * (ROAD_HALF + 0.85)
        taken = [(r[0][0] + r[1][0]) / 2 for r in rows[::3] if (r[0][1] + r[1][1]) / 2 * side > 0]
        if any(abs(fx - x) < 3.2 and fy * side > 0 for fx, fy in furniture) or any(abs(tx - x) < 5.5 for tx in taken):
            continue
        rows += _car_rows(x, y, 1.0, cols[rng.randrange(len(cols))], (PARKED_CAR, PARKED_CAR, POLE))
    parked = Boxes.build(rows) if rows else empty_boxes()
    return Movers(peds, cols[rng.randrange(len(cols))], cols[rng.randrange(len(cols))], parked)


def frame_boxes(layout: StreetLayout, movers: "Movers | None", t: float, c2w: Tensor) -> Boxes:
    """Everything that moves at a training frame (time ``t``, camera ``c2w [3, 4]``): the street's cars,
    kept clear of the camera's car, and the movers (None: none). The same boxes in the same order at
    every frame, so box ``k`` of two frames is one object."""
    cars = layout.car_boxes(t, avoid=(float(c2w[0, 3]), float(c2w[1, 3])))
    return cars if movers is None else Boxes.cat([cars, movers.boxes(t, c2w)])
