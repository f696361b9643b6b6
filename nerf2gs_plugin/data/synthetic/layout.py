"""The street's geometry in metres (x along the street, y across, z up), drawn from a seed.

A closed street canyon: a two-lane road (|y| < ROAD_HALF) on the plane z = 0, raised sidewalks
(boxes up to SIDEWALK_H, their road-facing sides are the kerb), rows of buildings of varying width,
height and colour on both sides with the facades at |y| = FACADE_Y, two end blocks closing the
street, poles with lamp arms and trees (trunk box + sphere crown) on the sidewalks, and cars (body,
cabin and wheel boxes) that drive along the lanes: the only thing that moves.
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass

import torch
from torch import Tensor

ROAD_HALF = 3.5
SIDEWALK_H = 0.15
FACADE_Y = 9.0  # 18 m between facades: bird's-eye views see mostly road and sidewalk, as in MatrixCity
STREET_HALF_LEN = 36.0  # buildings line x in [-36, 36]; end blocks beyond
CAR_RANGE = 33.0  # cars wrap around within |x| < CAR_RANGE
CROSSWALKS = (-14.0, 12.0)

# material ids
SKY, ROAD, SIDEWALK, BUILDING, POLE, TRUNK, CROWN, CAR_BODY, CAR_CABIN, CAR_WHEELS, PARKED_CAR = range(11)  # parked: static (movers.py)
GROUND_MATERIALS = (ROAD, SIDEWALK)
TRANSIENT_MATERIALS = (CAR_BODY, CAR_CABIN, CAR_WHEELS)


@dataclass
class Boxes:
    """Axis-aligned boxes: ``lo, hi [B, 3]``, ``material [B]`` long, ``colour [B, 3]``,
    and ``ident [B]`` (box index: varies the windows per building; cars get 10000+)."""

    lo: Tensor
    hi: Tensor
    material: Tensor
    colour: Tensor
    ident: Tensor

    @staticmethod
    def build(rows: list[tuple[tuple[float, float, float], tuple[float, float, float], int, tuple[float, float, float]]]) -> "Boxes":
        lo = torch.tensor([r[0] for r in rows], dtype=torch.float32).reshape(-1, 3)
        hi = torch.tensor([r[1] for r in rows], dtype=torch.float32).reshape(-1, 3)
        return Boxes(lo, hi, torch.tensor([r[2] for r in rows], dtype=torch.long), torch.tensor([r[3] for r in rows], dtype=torch.float32).reshape(-1, 3), torch.arange(len(rows)))

    @staticmethod
    def cat(parts: list["Boxes"]) -> "Boxes":
        return Boxes(*(torch.cat([getattr(p, k) for p in parts]) for k in ("lo", "hi", "material", "colour", "ident")))

    def __len__(self) -> int:
        return self.lo.shape[0]


@dataclass
class Spheres:
    centre: Tensor  # [S, 3]
    radius: Tensor  # [S]


@dataclass
class Car:
    x0: float  # position at t = 0 (m)
    lane_y: float
    direction: float  # +1 drives toward +x, -1 toward -x
    speed: float  # m/s
    colour: tuple[float, float, float]


@dataclass
class StreetLayout:
    """Everything static, plus the cars' motion; see the module docstring."""

    static: Boxes
    crowns: Spheres
    cars: list[Car]
    sun: Tensor  # [3] unit direction toward the sun
    seed: int

    def car_boxes(self, t: float, avoid: tuple[float, float] | None = None) -> Boxes:
        """The cars at time ``t`` (seconds). ``avoid = (x, y)``: a camera-carrying car there; a car
        in its lane less than 8 m ahead or 5 m behind is pushed 14 m on, so no car drives through
        the camera or fills its view."""
        rows = []
        span = 2 * CAR_RANGE
        for c in self.cars:
            x = (c.x0 + c.direction * c.speed * t + CAR_RANGE) % span - CAR_RANGE
            ahead = (x - avoid[0]) * c.direction if avoid is not None else 99.0
            if avoid is not None and abs(c.lane_y - avoid[1]) < 2.0 and -5.0 < ahead < 8.0:
                x = (x + c.direction * 14.0 + CAR_RANGE) % span - CAR_RANGE
            y, d = c.lane_y, c.direction
            body_col = c.colour
            glass = tuple(0.10 + 0.2 * v for v in body_col)
            rows.append(((x - 2.15, y - 0.9, 0.28), (x + 2.15, y + 0.9, 1.05), CAR_BODY, body_col))
            cab_lo, cab_hi = (x - 1.25, x + 0.85) if d > 0 else (x - 0.85, x + 1.25)
            rows.append(((cab_lo, y - 0.8, 1.05), (cab_hi, y + 0.8, 1.55), CAR_CABIN, glass))
            rows.append(((x - 1.75, y - 0.82, 0.0), (x + 1.75, y + 0.82, 0.28), CAR_WHEELS, (0.05, 0.05, 0.05)))
        if not rows:
            return empty_boxes()
        b = Boxes.build(rows)
        b.ident = b.ident + 10_000
        return b


def empty_boxes() -> Boxes:
    z = torch.zeros(0, 3)
    return Boxes(z, z.clone(), torch.zeros(0, dtype=torch.long), z.clone(), torch.zeros(0, dtype=torch.long))


def _palette(rng: random.Random) -> tuple[float, float, float]:
    """A plausible facade colour: warm plaster, brick, grey concrete, pale blue or green."""
    bases = [(0.80, 0.72, 0.60), (0.62, 0.34, 0.26), (0.62, 0.62, 0.60), (0.66, 0.74, 0.80), (0.74, 0.78, 0.64), (0.86, 0.82, 0.74), (0.70, 0.52, 0.40)]
    b = bases[rng.randrange(len(bases))]
    j = [rng.uniform(-0.05, 0.05) for _ in range(3)]
    return tuple(min(1.0, max(0.0, v + j[i])) for i, v in enumerate(b))  # type: ignore[return-value]


def build_layout(seed: int, num_cars: int = 6) -> StreetLayout:
    """The street for ``seed``: building rows, sidewalks, street furniture, cars and the sun."""
    rng = random.Random(seed)
    rows: list = []
    bid = 0
    for side in (-1.0, 1.0):
        x = -STREET_HALF_LEN
        while x < STREET_HALF_LEN - 1e-6:
            w = min(rng.uniform(7.0, 13.0), STREET_HALF_LEN - x)
            if STREET_HALF_LEN - (x + w) < 4.0:
                w = STREET_HALF_LEN - x
            h = rng.uniform(8.0, 20.0)
            setback = rng.choice([0.0, 0.0, 0.3, 0.6])
            y0, y1 = FACADE_Y + setback, FACADE_Y + 16.0
            lo, hi = (x, min(side * y0, side * y1), 0.0), (x + w, max(side * y0, side * y1), h)
            rows.append((lo, hi, BUILDING, _palette(rng)))
            bid += 1
            x += w
        # sidewalk (its road-facing side is the kerb), reaching under the facades
        rows.append(((-STREET_HALF_LEN, min(side * ROAD_HALF, side * (FACADE_Y + 0.7)), 0.0),
                     (STREET_HALF_LEN, max(side * ROAD_HALF, side * (FACADE_Y + 0.7)), SIDEWALK_H), SIDEWALK, (0.6, 0.6, 0.6)))
    for end in (-1.0, 1.0):  # end blocks closing the street
        x0, x1 = sorted((end * STREET_HALF_LEN, end * (STREET_HALF_LEN + 10.0)))
        rows.append(((x0, -FACADE_Y - 16.0, 0.0), (x1, FACADE_Y + 16.0, rng.uniform(12.0, 18.0)), BUILDING, _palette(rng)))
    centres, radii = [], []
    for side in (-1.0, 1.0):
        x = -STREET_HALF_LEN + rng.uniform(3.0, 6.0)
        k = 0
        while x < STREET_HALF_LEN - 3.0:
            y = side * (ROAD_HALF + 0.7)
            if k % 2 == 0:  # pole with a lamp arm over the road
                rows.append(((x - 0.08, y - 0.08, 0.0), (x + 0.08, y + 0.08, 6.0), POLE, (0.25, 0.27, 0.30)))
                rows.append(((x - 0.06, min(y, y - side * 1.6), 5.8), (x + 0.06, max(y, y - side * 1.6), 5.95), POLE, (0.25, 0.27, 0.30)))
            else:  # tree
                ty = side * (ROAD_HALF + 1.3)
                rows.append(((x - 0.15, ty - 0.15, 0.0), (x + 0.15, ty + 0.15, 3.2), TRUNK, (0.36, 0.26, 0.16)))
                r = rng.uniform(1.2, 1.6)
                centres.append((x, ty, 3.2 + 0.8 * r))
                radii.append(r)
            k += 1
            x += rng.uniform(8.0, 12.0)
    static = Boxes.build(rows)
    crowns = Spheres(torch.tensor(centres, dtype=torch.float32).reshape(-1, 3), torch.tensor(radii, dtype=torch.float32))
    car_cols = [(0.75, 0.10, 0.10), (0.10, 0.25, 0.65), (0.90, 0.90, 0.88), (0.12, 0.12, 0.13), (0.85, 0.65, 0.10), (0.20, 0.50, 0.30), (0.55, 0.55, 0.58)]
    cars = []
    for i in range(num_cars):
        d = 1.0 if i % 2 == 0 else -1.0
        lane = -d * ROAD_HALF / 2 + rng.uniform(-0.25, 0.25)  # right-hand traffic
        cars.append(Car(rng.uniform(-CAR_RANGE, CAR_RANGE), lane, d, rng.uniform(3.0, 9.0), car_cols[rng.randrange(len(car_cols))]))
    az, el = math.radians(rng.uniform(25.0, 65.0)), math.radians(rng.uniform(40.0, 55.0))
    sun = torch.tensor([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)], dtype=torch.float32)
    return StreetLayout(static, crowns, cars, sun, seed)
