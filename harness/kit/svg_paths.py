"""Compact SVG path data and numbers: coordinates rounded, paths written relative and thinned.

A figure's path data is most of its size. `compact_path` rounds a path's numbers to
`SVG_DECIMALS`, writes its line segments as relative moves in short integers and drops the
points of a line that lie within `LINE_TOLERANCE` points of the thinned line (Douglas-Peucker:
D. H. Douglas & T. K. Peucker, The Canadian Cartographer 10 (1973) 112-122); `dedupe_style`
keeps one declaration of each property.
"""

from __future__ import annotations

import math
import re

__all__ = ["round_numbers", "compact_path", "dedupe_style", "short_number", "simplify", "subpaths",
           "relative_path", "LINE_SCALE", "LINE_TOLERANCE", "CLOSED_SCALE", "SVG_DECIMALS"]

# Coordinates in the SVG are rounded to this many decimals of a point (1/10 pt is far below
# what a screen shows; the full-precision numbers are in each figure's CSV).
SVG_DECIMALS = 1


_NUMBER = re.compile(r"-?\d+\.\d+")


def round_numbers(text: str) -> str:
    def one(m: re.Match) -> str:
        s = f"{float(m.group(0)):.{SVG_DECIMALS}f}".rstrip("0").rstrip(".")
        return "0" if s in ("-0", "") else s

    return _NUMBER.sub(one, text)


def compact_path(d: str, min_points: int = 3) -> str:
    d = round_numbers(" ".join(d.split()))
    return relative_path(re.sub(r"\s*([MLCQZHVAmlcqzhva])\s*", r"\1", d), tolerance=LINE_TOLERANCE,
                          min_points=min_points)


def dedupe_style(style: str) -> str:
    """Each property once, with the value that wins (the last)."""
    last: dict[str, str] = {}
    for decl in style.split(";"):
        name, _, value = decl.partition(":")
        last.pop(name, None)
        last[name] = value
    return ";".join(f"{k}:{v}" for k, v in last.items() if k)


def short_number(v: int, scale: int) -> str:
    """`v / scale` (scale 1 or 10) as its shortest SVG number (15/10 -> 1.5, -5/10 -> -.5)."""
    if scale == 1:
        return str(v)
    sign, a = ("-" if v < 0 else ""), abs(v)
    whole, frac = divmod(a, 10)
    if not frac:
        return f"{sign}{whole}"
    return f"{sign}{whole if whole else ''}.{frac}"


# Data lines (paths of three points or more) are drawn to whole points: a point is 1.3 CSS
# pixels at the figure's own size and less where the page scales it down, so the line looks the
# same; its numbers are in the figure's CSV.
LINE_SCALE = 1
# A data line's vertices closer than this (in points) to the straight line through their
# neighbours are left out (Douglas-Peucker): a matplotlib line of a few dozen points is never
# simplified by matplotlib itself, yet runs of nearly collinear points are most of its bytes.
LINE_TOLERANCE = 0.4


def simplify(points: list[tuple[int, int]], tolerance: float) -> list[tuple[int, int]]:
    """Douglas-Peucker: the points whose omission moves the line by more than `tolerance`."""
    if len(points) < 3:
        return points
    keep = [False] * len(points)
    keep[0] = keep[-1] = True
    stack = [(0, len(points) - 1)]
    while stack:
        i, j = stack.pop()
        if j <= i + 1:
            continue
        (ax, ay), (bx, by) = points[i], points[j]
        dx, dy = bx - ax, by - ay
        norm = math.hypot(dx, dy)
        worst, at = -1.0, i
        for k in range(i + 1, j):
            px, py = points[k]
            dist = (abs(dx * (py - ay) - dy * (px - ax)) / norm if norm
                    else math.hypot(px - ax, py - ay))
            if dist > worst:
                worst, at = dist, k
        if worst > tolerance:
            keep[at] = True
            stack += [(i, at), (at, j)]
    return [p for p, k in zip(points, keep, strict=True) if k]


_COMMAND = re.compile(r"([MLZz])([^MLZz]*)")
_PAIR = re.compile(r"(-?[\d.]+) (-?[\d.]+)")
# Closed shapes (filled regions, bars) keep tenths of a point: their edges meet other shapes.
CLOSED_SCALE = 10


def subpaths(d: str) -> list[tuple[list[tuple[float, float]], bool]] | None:
    """`d` as (points, closed) sub-paths when it holds only absolute moves, lines (one point
    each) and closes; None otherwise."""
    out: list[tuple[list[tuple[float, float]], bool]] = []
    covered = 0
    for m in _COMMAND.finditer(d):
        if m.start() != covered:
            return None
        covered = m.end()
        cmd, args = m.group(1), m.group(2)
        if cmd in "Zz":
            if args or not out or out[-1][1]:
                return None
            out[-1] = (out[-1][0], True)
            continue
        pair = _PAIR.fullmatch(args)
        if pair is None:
            return None
        point = (float(pair.group(1)), float(pair.group(2)))
        if cmd == "M":
            out.append(([point], False))
        elif not out or out[-1][1]:
            return None
        else:
            out[-1][0].append(point)
    return out if covered == len(d) and out else None


def relative_path(d: str, scale: int = LINE_SCALE, tolerance: float = 0.0, min_points: int = 3) -> str:
    """A path of absolute moves, lines and closes only (what matplotlib writes for data lines,
    filled regions and bars) in relative steps of 1/`scale` point (closed sub-paths: of
    1/CLOSED_SCALE point), horizontal and vertical steps as `h`/`v`: the points rounded first,
    so no error accumulates; about half the bytes. With `tolerance` (points), each sub-path is
    thinned by `simplify`. Any other path, or one of fewer than `min_points` points, is
    returned unchanged."""
    subs = subpaths(d) if d.startswith("M") else None
    if subs is None or sum(len(p) for p, _ in subs) < min_points:
        return d
    if any(closed for _, closed in subs):
        scale = max(scale, CLOSED_SCALE)
    out: list[str] = []
    px = py = 0
    last = ""

    def put(letter: str, *values: int) -> None:
        nonlocal last
        nums = [short_number(v, scale) for v in values]
        text = ""
        # a repeated command (after a move, a line) needs no letter, only a separator
        implicit = letter == last or (letter == "l" and last == "m")
        for k, n in enumerate(nums):
            if k == 0 and not implicit:
                text += letter + n
            else:
                text += ("" if n.startswith("-") else " ") + n
        out.append(text)
        last = "l" if letter == "m" else letter

    for points, closed in subs:
        grid = [(round(x * scale), round(y * scale)) for x, y in points]
        if tolerance > 0:
            grid = simplify(grid, tolerance * scale)
        sx, sy = grid[0]
        if not out:
            out.append(f"M{short_number(sx, scale)} {short_number(sy, scale)}")
            last = "M"  # pairs after an absolute move would be absolute lines: letters needed
        else:
            put("m", sx - px, sy - py)
        px, py = sx, sy
        for X, Y in grid[1:]:
            if X == px and Y == py:
                continue  # a step of zero length draws nothing
            if Y == py:
                put("h", X - px)
            elif X == px:
                put("v", Y - py)
            else:
                put("l", X - px, Y - py)
            px, py = X, Y
        if closed:
            out.append("z")
            last = "z"
            px, py = sx, sy  # a close returns to the sub-path's start
    return "".join(out)
