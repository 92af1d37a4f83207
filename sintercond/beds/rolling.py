"""Sequential deposition with rolling: spheres dropped one by one that roll down the pile to a stable rest.

Each sphere falls vertically at a random lateral position until it touches
the floor or a sphere already down, then rolls, without slipping off the
geometry and without inertia, down the surfaces it touches until gravity is
balanced by the supports' reactions (Visscher & Bolsterli 1972, Nature 239,
504; Jodrey & Tory 1979 for unequal spheres): on one sphere it rolls down a
great circle of that sphere; on two (or a sphere and a side wall) along the
circle where the two contact surfaces meet; with three supports it stops if
the upward reactions that balance its weight are all pushes, and otherwise
leaves the support that would have to pull. A sphere that reaches the floor
stops there. Each placed sphere is at rest under gravity on its supports
(the packing is stable as a frictional powder's is: nothing is relaxed
afterwards), no two spheres overlap by more than ``overlap``, and every sphere
touches the floor or one to three supports, so none is isolated.

Every motion is an arc of a circle ``p(phi) = q + s (cos(phi) u + sin(phi) w)``
(or, falling, a vertical line), and every event along it (touching a new
sphere, the floor or a wall, a support whose reaction turns to a pull, the
arc's lowest point) is the first root of ``A cos(phi) + B sin(phi) = E``,
solved in closed form: no time steps, so a bed of ``n`` spheres costs ``O(n)``
arcs on a three-dimensional bin grid of the spheres already down.

Beds from it are looser than the frictionless relaxation of
:func:`sintercond.beds.settle.relax_under_gravity` (each sphere stays where it first
found three supports, as a poured frictional powder does): solid fraction
about 0.58 for equal spheres (Visscher & Bolsterli's figure) and 0.6 for the
20-60 um powders of the examples, against 0.65-0.66 relaxed; a mean
coordination close to 6 (three supports below each sphere, three it
supports).
"""

from __future__ import annotations

import dataclasses
import math
from typing import NamedTuple

import numpy as np

MAX_STAGES = 200
"""Most arcs one sphere may roll along before it is left where it is (and counted in :class:`RollReport`)."""

_TOL = 1e-10
"""Relative tolerance of a touch (in units of the contact distance) and of an event's angle (rad)."""


@dataclasses.dataclass(frozen=True)
class RollReport:
    """How the spheres of :func:`roll_deposit` came to rest.

    Attributes:
      on_floor: spheres resting on the floor.
      on_three: spheres at rest on three supports (spheres or side walls).
      on_two: spheres at rest at the lowest point of the circle of two supports (wedged between them).
      unresolved: spheres still rolling after :data:`MAX_STAGES` arcs, left touching their supports (0 in
        every bed measured).
      arcs: arcs rolled in all (falls included).
    """

    on_floor: int
    on_three: int
    on_two: int
    unresolved: int
    arcs: int


class _Grid:
    """The spheres down so far on a three-dimensional grid of cubic bins of side ``width`` (lateral ``[0, L]^2``)."""

    def __init__(self, n, lateral_size, width, capacity=8):
        self.width = width
        self.nxy = max(1, int(math.ceil(lateral_size / width)))
        self.members = np.full((self.nxy, self.nxy, 4, capacity), n, np.int64)
        self.counts = np.zeros((self.nxy, self.nxy, 4), np.int64)
        self.n = n

    def _bin(self, value, top):
        return int(min(max(value / self.width, 0.0), top))

    def add(self, k, p):
        bx, by = self._bin(p[0], self.nxy - 1), self._bin(p[1], self.nxy - 1)
        bz = int(max(p[2] / self.width, 0.0))
        if bz >= self.members.shape[2]:  # a taller pile: twice the layers
            grow = max(bz + 1, 2 * self.members.shape[2]) - self.members.shape[2]
            self.members = np.concatenate([self.members, np.full((self.nxy, self.nxy, grow, self.members.shape[3]),
                                                                 self.n, np.int64)], axis=2)
            self.counts = np.concatenate([self.counts, np.zeros((self.nxy, self.nxy, grow), np.int64)], axis=2)
        if self.counts[bx, by, bz] == self.members.shape[3]:
            self.members = np.concatenate([self.members, np.full_like(self.members, self.n)], axis=3)
        self.members[bx, by, bz, self.counts[bx, by, bz]] = k
        self.counts[bx, by, bz] += 1

    def within(self, lo, hi):
        """Indices of the spheres whose centres may lie in the box ``[lo, hi]`` (``[3]`` each)."""
        x0, x1 = self._bin(lo[0], self.nxy - 1), self._bin(hi[0], self.nxy - 1)
        y0, y1 = self._bin(lo[1], self.nxy - 1), self._bin(hi[1], self.nxy - 1)
        top = self.members.shape[2] - 1
        z0, z1 = self._bin(lo[2], top), self._bin(hi[2], top)
        block = self.counts[x0:x1 + 1, y0:y1 + 1, z0:z1 + 1]
        most = int(block.max(initial=0))
        if most == 0:
            return np.zeros(0, np.int64)
        found = self.members[x0:x1 + 1, y0:y1 + 1, z0:z1 + 1, :most].ravel()
        return found[found < self.n]


def _first_entry(A, B, E, phi_end):
    """The first angle in ``[0, phi_end]`` at which ``h = A cos(phi) + B sin(phi) - E`` turns negative, per row.

    ``inf`` where ``h`` stays >= 0 on the arc. A row already at ``h <= 0`` (within the touch tolerance) and
    decreasing enters at 0; one already there and increasing is being left, not entered.
    """
    M = np.hypot(A, B)
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = np.where(M > 0, E / np.where(M > 0, M, 1.0), np.inf)
        entry = np.mod(np.arctan2(B, A) + np.arccos(np.clip(ratio, -1.0, 1.0)), 2.0 * np.pi)
    entry = np.where(np.abs(ratio) <= 1.0, entry, np.inf)
    h0, slope0 = A - E, B  # h and dh/dphi at phi = 0
    scale = np.maximum(M, np.abs(E))
    now = (h0 <= _TOL * scale) & (slope0 < 0)
    entry = np.where(now, 0.0, np.where(entry > 2.0 * np.pi - _TOL, np.inf, entry))
    entry = np.where(entry <= phi_end, entry, np.inf)
    return entry


def _first_entry_scalar(A, B, E, phi_end):
    """:func:`_first_entry` of one row, in Python floats."""
    M = math.hypot(A, B)
    if A - E <= _TOL * max(M, abs(E)) and B < 0:
        return 0.0
    if M == 0.0 or abs(E / M) > 1.0:
        return math.inf
    entry = (math.atan2(B, A) + math.acos(E / M)) % (2.0 * math.pi)
    return entry if entry <= phi_end and entry <= 2.0 * math.pi - _TOL else math.inf


@dataclasses.dataclass
class _Supports:
    """What a rolling sphere touches: sphere indices and wall numbers (0: x = r, 1: x = L - r, 2: y = r, 3: y = L - r)."""

    spheres: list
    walls: list

    def count(self):
        return len(self.spheres) + len(self.walls)


def _leave(supports, m):
    """Drop the ``m``-th support (spheres first, then walls)."""
    if m < len(supports.spheres):
        supports.spheres.pop(m)
    else:
        supports.walls.pop(m - len(supports.spheres))


_UP = np.array([0.0, 0.0, 1.0])

_WALL_NORMALS = np.array([[1.0, 0, 0], [-1.0, 0, 0], [0, 1.0, 0], [0, -1.0, 0]])


def _wall_offsets(reach, L):
    """``d`` of each side wall's plane ``n . p = d`` for a sphere that reaches ``reach`` (its centre's allowed region)."""
    return np.array([reach, -(L - reach), reach, -(L - reach)])


def _norm(v):
    """Length of a 3-vector (math on its three numbers: NumPy's norm costs more than the arithmetic here)."""
    return math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2])


def _reactions(p, supports, centres):
    """Reactions ``lambda`` with ``sum lambda_k n_k = z``: solved for three supports, least squares (the normal
    equations of the Gram matrix) for fewer."""
    normals = [(p - centres[k]) / _norm(p - centres[k]) for k in supports.spheres]
    normals += [_WALL_NORMALS[w] for w in supports.walls]
    if len(normals) == 2:  # the projection of z on the normals' plane: the Gram matrix [[1, c], [c, 1]]
        c = float(np.dot(normals[0], normals[1]))
        if 1.0 - c * c > _TOL:
            z0, z1 = normals[0][2], normals[1][2]
            return np.array([z0 - c * z1, z1 - c * z0]) / (1.0 - c * c)
    N = np.array(normals).T
    if N.shape[1] == 3:
        try:
            return np.linalg.solve(N, _UP)
        except np.linalg.LinAlgError:  # coplanar supports: the least-squares reactions
            pass
    return np.linalg.lstsq(N, _UP, rcond=None)[0]


PROGRESS_EVERY = 500
"""Spheres between two calls of :func:`roll_deposit`'s ``progress``."""

MAX_OVERLAP = 0.01
"""Largest relative overlap :func:`roll_deposit` takes (its arcs are those of touching spheres; a larger overlap is a
neck, which ``sinter_swelling`` or the sintering physics make)."""


SURFACE_POINTS = 64
"""Lateral grid (``SURFACE_POINTS^2`` points) on which :func:`roll_deposit` follows the pile's mean surface height: the
grid of :func:`sintercond.beds.packing.Packing`'s ``height``."""


class _Pile(NamedTuple):
    """What a rolling sphere meets: the spheres down so far (``centres`` ``[n + 1, 3]``, the last the grid's padding
    at infinity; ``radii`` ``[n]``) in their ``grid``, the largest radius and the contact distance factor
    ``shrink = 1 - overlap``."""

    centres: np.ndarray
    radii: np.ndarray
    grid: _Grid
    r_max: float
    shrink: float


class _Arc(NamedTuple):
    """The circle a sphere rolls along, ``q + s (cos(phi) u + sin(phi) w)`` (``u``, ``w`` orthonormal, ``w`` the
    downhill tangent at ``phi = 0``), up to ``phi_low``, its lowest point or the equator of its one support."""

    q: np.ndarray
    s: float
    u: np.ndarray
    w: np.ndarray
    phi_low: float


def _fall(p, R, pile: _Pile):
    """``(height, sphere)`` where a sphere of radius ``R`` falling straight down from ``p`` first rests on a sphere
    of the pile, or None when it reaches the floor first."""
    centres, radii, shrink = pile.centres, pile.radii, pile.shrink
    reach = R + pile.r_max
    cand = pile.grid.within(np.array([p[0] - reach, p[1] - reach, -np.inf]), np.array([p[0] + reach, p[1] + reach, p[2]]))
    rho = (R + radii[cand]) * shrink
    lateral2 = (centres[cand, 0] - p[0]) ** 2 + (centres[cand, 1] - p[1]) ** 2
    above = np.sqrt(np.maximum(rho**2 - lateral2, 0.0))  # contact height above the centre below
    hit = (lateral2 < rho**2) & (above > _TOL * rho)  # a sphere left at its equator is not hit again
    z_rest = np.where(hit, centres[cand, 2] + above, -np.inf)
    z_rest = np.where(z_rest <= p[2] + _TOL * R, z_rest, -np.inf)  # below where it is
    best = int(np.argmax(z_rest)) if len(cand) else -1
    if best < 0 or z_rest[best] <= R * shrink:
        return None
    return z_rest[best], int(cand[best])


def _rolling_arc(p, R, sup: _Supports, offsets, centres, rng):
    """The :class:`_Arc` a sphere at ``p`` rolls along on its supports ``sup``; ``"two"`` where it rests on two
    (the circle is a point, or ``p`` its lowest point); None where the supports changed first (the sphere is at or
    below its one support's equator and leaves it, or one of two supports would pull and is left)."""
    if len(sup.spheres) == 1 and not sup.walls:
        c = centres[sup.spheres[0]]
        q, s = c, _norm(p - c)
        u = (p - q) / s
        if u[2] <= _TOL:  # at or below the equator: it leaves the sphere
            sup.spheres = []
            return None
        uh = float(np.hypot(u[0], u[1]))
        if uh < _TOL:  # on top: any way down
            angle = rng.uniform(0.0, 2.0 * np.pi)
            heading = np.array([math.cos(angle), math.sin(angle)])
        else:
            heading = u[:2] / uh
        w = np.array([*(u[2] * heading), -uh])  # the tangent down the great circle
        w -= np.dot(w, u) * u
        w /= _norm(w)
        return _Arc(q, s, u, w, math.atan2(u[2], -w[2]))  # the equator: past it the sphere falls
    lam = _reactions(p, sup, centres)
    if np.min(lam) < -_TOL:  # one support would pull: roll on the other alone
        _leave(sup, int(np.argmin(lam)))
        return None
    if len(sup.spheres) == 2:
        ca, cb = centres[sup.spheres[0]], centres[sup.spheres[1]]
        ra, rb = _norm(p - ca), _norm(p - cb)
        d = _norm(cb - ca)
        axis = (cb - ca) / d
        along = (d * d + ra * ra - rb * rb) / (2.0 * d)
        q = ca + along * axis
    else:  # one sphere and one wall
        ca = centres[sup.spheres[0]]
        axis = _WALL_NORMALS[sup.walls[0]]
        q = ca + (offsets[sup.walls[0]] - np.dot(axis, ca)) * axis
    u = p - q
    u -= np.dot(u, axis) * axis
    s = _norm(u)
    if s < _TOL * R:  # the circle is a point: nowhere to roll
        return "two"
    u /= s
    w = np.array([axis[1] * u[2] - axis[2] * u[1], axis[2] * u[0] - axis[0] * u[2], axis[0] * u[1] - axis[1] * u[0]])
    if w[2] > 0:
        w = -w
    if w[2] > -_TOL:  # at the circle's lowest point already
        return "two"
    return _Arc(q, s, u, w, math.atan2(-w[2], -u[2]) % (2.0 * np.pi))


def _contact_events(arc: _Arc, R, offsets, sup: _Supports, pile: _Pile):
    """Where on the arc the rolling sphere first touches another sphere or a plane: ``(cand, sphere_at,
    free_walls, plane_at)``, the angles of the candidate spheres ``cand`` and of the planes ``free_walls`` (the
    side walls 0-3 and the floor 4 it does not lean on; inf: not on the arc)."""
    q, s, u, w, phi_low = arc
    centres = pile.centres
    cand = pile.grid.within(q - s - R - pile.r_max, q + s + R + pile.r_max)
    for m in sup.spheres:
        cand = cand[cand != m]
    rho = (R + pile.radii[cand]) * pile.shrink
    rel = q[None, :] - centres[cand]
    A = 2.0 * s * rel @ u
    B = 2.0 * s * rel @ w
    E = rho**2 - np.sum(rel**2, axis=1) - s * s
    sphere_at = _first_entry(A, B, E, phi_low)
    # floor (z >= R) and side walls (n . p >= d): h = n.q - d + s (n.u cos + n.w sin)
    planes = np.vstack([_WALL_NORMALS, [[0.0, 0.0, 1.0]]])
    plane_d = np.append(offsets, R * pile.shrink)
    free_walls = [m for m in range(5) if m not in sup.walls]
    plane_at = _first_entry(s * planes[free_walls] @ u, s * planes[free_walls] @ w,
                            plane_d[free_walls] - planes[free_walls] @ q, phi_low)
    return cand, sphere_at, free_walls, plane_at


def _pull_events(p, arc: _Arc, sup: _Supports, centres):
    """``[supports]``: the angle on the arc at which each of two supports' reaction turns to a pull (inf: never):
    ``lambda_k(phi)`` is linear in ``(cos, sin, 1)``."""
    q, s, u, w, phi_low = arc
    lam_at = np.full(sup.count(), np.inf)
    if sup.count() != 2:
        return lam_at
    normals_u, normals_w, normals_q = [], [], []
    for m in sup.spheres:
        rk = _norm(p - centres[m])
        normals_u.append(s * u / rk)
        normals_w.append(s * w / rk)
        normals_q.append((q - centres[m]) / rk)
    for m in sup.walls:
        normals_u.append(np.zeros(3))
        normals_w.append(np.zeros(3))
        normals_q.append(_WALL_NORMALS[m])
    n0 = normals_q[0] + normals_u[0]  # the normals at phi = 0, for their (constant) cosine
    n1 = normals_q[1] + normals_u[1]
    cosine = float(np.dot(n0, n1))
    if 1.0 - cosine**2 > _TOL:
        for a, b in ((0, 1), (1, 0)):  # lambda_a (1 - c^2) = n_a.z - c n_b.z
            zu = normals_u[a][2] - cosine * normals_u[b][2]
            zw = normals_w[a][2] - cosine * normals_w[b][2]
            zq = normals_q[a][2] - cosine * normals_q[b][2]
            lam_at[a] = _first_entry_scalar(zu, zw, -zq, phi_low)
            if lam_at[a] == 0.0:
                lam_at[a] = _TOL  # leave it now (below), not an endless loop
    return lam_at


def _raise_surface(surface, p, R, spacing):
    """The pile's surface heights on the grid points (spacing ``spacing``) below a sphere at ``p`` raised to its
    cap, in place."""
    lo = np.maximum(np.floor((p[:2] - R) / spacing - 0.5).astype(int), 0)
    hi = np.minimum(np.ceil((p[:2] + R) / spacing - 0.5).astype(int), SURFACE_POINTS - 1)
    gx = (np.arange(lo[0], hi[0] + 1) + 0.5) * spacing
    gy = (np.arange(lo[1], hi[1] + 1) + 0.5) * spacing
    rho2 = (gx[:, None] - p[0]) ** 2 + (gy[None, :] - p[1]) ** 2
    cap = np.where(rho2 < R * R, p[2] + np.sqrt(np.maximum(R * R - rho2, 0.0)), 0.0)
    block = surface[lo[0]:hi[0] + 1, lo[1]:hi[1] + 1]
    np.maximum(block, cap, out=block)


def roll_deposit(radii, lateral_size, rng, overlap=0.0, progress=None, fill_height=None):
    """Drop ``radii`` one by one into the open box ``[0, L]^2 x [0, inf)`` and let each roll to rest.

    Args:
      radii: ``[n]`` (length), in the order they are dropped; ``2 max(radii) < lateral_size``.
      lateral_size: the box's side ``L`` (length).
      rng: a NumPy ``Generator`` (the lateral drop positions, and the roll direction off a sphere's top).
      overlap: each sphere comes to rest at ``(r_i + r_j)(1 - overlap)`` from the spheres it touches
        (relative overlap, in ``[0, MAX_OVERLAP]``): 0 gives point contacts; a small value makes the supports
        contacts that :func:`sintercond.laws.geometry.contacts` and the pipe network count.
      progress: ``progress("rolling", spheres down, n, spheres down, n)`` every :data:`PROGRESS_EVERY` spheres
        and at the end, or None.
      fill_height: stop once the pile's mean surface height (the highest sphere surface above each point of a
        :data:`SURFACE_POINTS`-square lateral grid, averaged) reaches this (length); None drops every sphere.

    Returns:
      ``(centres [m, 3], RollReport)`` of the ``m`` spheres dropped (the first ``m`` of ``radii``; all of them
      without ``fill_height``).

    Raises:
      ValueError: radii not all finite and > 0, a sphere wider than the box, or ``overlap`` outside its range.
    """
    radii = np.asarray(radii, dtype=np.float64)
    n = len(radii)
    L = float(lateral_size)
    if radii.ndim != 1 or not np.all(np.isfinite(radii) & (radii > 0)):
        raise ValueError("radii must be an [n] array of finite values > 0")
    if not (math.isfinite(L) and 2.0 * float(np.max(radii, initial=0.0)) < L):
        raise ValueError(f"lateral_size must be finite and exceed the largest diameter; got {lateral_size!r}")
    if isinstance(overlap, bool) or not (0.0 <= overlap <= MAX_OVERLAP):
        raise ValueError(f"overlap must be in [0, {MAX_OVERLAP}] (relative); got {overlap!r}")
    shrink = 1.0 - float(overlap)
    r_max = float(np.max(radii, initial=0.0))
    centres = np.zeros((n + 1, 3))
    centres[n] = np.inf  # the padding index of the grid
    grid = _Grid(n, L, 2.0 * r_max * (1.0 + 1e-9))
    tallies = {"floor": 0, "three": 0, "two": 0, "unresolved": 0}
    arcs = 0
    spacing = L / SURFACE_POINTS
    surface = np.zeros((SURFACE_POINTS, SURFACE_POINTS))
    placed = n
    pile = _Pile(centres, radii, grid, r_max, shrink)
    for k, R in enumerate(radii):
        p = np.array([*rng.uniform(R, L - R, 2), np.inf])
        sup = _Supports([], [])
        offsets = _wall_offsets(R * shrink, L)
        outcome = "unresolved"
        for _ in range(MAX_STAGES):
            arcs += 1
            if not sup.spheres:  # nothing to roll on (walls are vertical): fall
                sup.walls = []
                below = _fall(p, R, pile)
                if below is None:
                    p[2] = R * shrink
                    outcome = "floor"
                    break
                p[2], support = below
                sup.spheres = [support]
                continue
            arc = _rolling_arc(p, R, sup, offsets, centres, rng)
            if arc is None:
                continue
            if arc == "two":
                outcome = "two"
                break
            # events on the arc: new spheres, the floor, the walls, a support that would pull
            cand, sphere_at, free_walls, plane_at = _contact_events(arc, R, offsets, sup, pile)
            lam_at = _pull_events(p, arc, sup, centres)
            first = min(float(np.min(sphere_at, initial=np.inf)), float(np.min(plane_at, initial=np.inf)),
                        float(np.min(lam_at, initial=np.inf)))
            phi = min(first, arc.phi_low)
            p = arc.q + arc.s * (math.cos(phi) * arc.u + math.sin(phi) * arc.w)
            if phi == arc.phi_low and first > arc.phi_low:  # the arc's end: the equator (1 support) or a stable wedge
                if sup.count() == 1:
                    sup.spheres = []
                    continue
                outcome = "two"
                break
            if float(np.min(lam_at, initial=np.inf)) == first:
                _leave(sup, int(np.argmin(lam_at)))
                continue
            if float(np.min(plane_at, initial=np.inf)) == first:
                wall = free_walls[int(np.argmin(plane_at))]
                if wall == 4:
                    p[2] = R * shrink
                    outcome = "floor"
                    break
                sup.walls.append(wall)
            else:
                sup.spheres.append(int(cand[int(np.argmin(sphere_at))]))
            if sup.count() == 3 or (len(sup.walls) == 2 and sup.spheres):
                lam = _reactions(p, sup, centres)
                if np.all(lam >= -_TOL):
                    outcome = "three"
                    break
                _leave(sup, int(np.argmin(lam)))
            if len(sup.walls) == 2 and not sup.spheres:
                sup.walls = []
        tallies[outcome] += 1
        p[:2] = np.clip(p[:2], R * shrink, L - R * shrink)
        centres[k] = p
        grid.add(k, p)
        if fill_height is not None:  # the sphere's cap over the grid points below it
            _raise_surface(surface, p, R, spacing)
        done = fill_height is not None and float(surface.mean()) >= fill_height
        if progress is not None and ((k + 1) % PROGRESS_EVERY == 0 or k + 1 == n or done):
            progress("rolling", k + 1, n, k + 1, n)
        if done:
            placed = k + 1
            break
    report = RollReport(tallies["floor"], tallies["three"], tallies["two"], tallies["unresolved"], arcs)
    return centres[:placed], report
