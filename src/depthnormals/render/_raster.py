"""Compiled kernels of the z-buffer renderer (numba, cached).

Each triangle is clipped against the near plane ``z = near`` (Sutherland-Hodgman, giving a
convex polygon of at most four vertices), projected, and binned into square screen tiles.
Tiles are rasterised in parallel; inside a tile faces are visited in index order, so the
result does not depend on the thread count. A pixel is covered when its integer position
lies inside the projected polygon (edges inclusive, with a 1e-9 pixel tolerance so shared
edges never leave cracks); its depth is the exact intersection of its ray with the plane of
the triangle, ``z = c / (n . r)`` with ``r = ((u - cx) / fx, (v - cy) / fy, 1)``. On equal
depth the lower face index wins.
"""

from __future__ import annotations

import numba as nb
import numpy as np

TILE = 32
_EDGE_TOL = 1e-9  # pixels


@nb.njit(cache=True)
def setup_faces(vc, faces, fx, fy, cx, cy, width, height, near):  # pragma: no cover - compiled
    """Per face: camera-facing unit normal, plane offset, projected clipped polygon and its
    float bounding box (umin, umax, vmin, vmax); ``nvert`` is 0 for faces not drawn."""
    nf = faces.shape[0]
    normal = np.zeros((nf, 3))
    offset = np.zeros(nf)
    poly = np.zeros((nf, 4, 2))
    nvert = np.zeros(nf, dtype=np.int32)
    fbox = np.zeros((nf, 4))
    pts = np.empty((3, 3))
    clip = np.empty((4, 3))
    for f in range(nf):
        nin = 0
        for k in range(3):
            for j in range(3):
                pts[k, j] = vc[faces[f, k], j]
            if pts[k, 2] >= near:
                nin += 1
        if nin == 0:
            continue
        # clip against z >= near
        m = 0
        for k in range(3):
            k1 = (k + 1) % 3
            in0 = pts[k, 2] >= near
            in1 = pts[k1, 2] >= near
            if in0:
                clip[m, 0] = pts[k, 0]
                clip[m, 1] = pts[k, 1]
                clip[m, 2] = pts[k, 2]
                m += 1
            if in0 != in1:
                t = (near - pts[k, 2]) / (pts[k1, 2] - pts[k, 2])
                clip[m, 0] = pts[k, 0] + t * (pts[k1, 0] - pts[k, 0])
                clip[m, 1] = pts[k, 1] + t * (pts[k1, 1] - pts[k, 1])
                clip[m, 2] = near
                m += 1
        if m < 3:
            continue
        umin = np.inf
        umax = -np.inf
        vmin = np.inf
        vmax = -np.inf
        for k in range(m):
            pu = fx * clip[k, 0] / clip[k, 2] + cx
            pv = fy * clip[k, 1] / clip[k, 2] + cy
            poly[f, k, 0] = pu
            poly[f, k, 1] = pv
            umin = min(umin, pu)
            umax = max(umax, pu)
            vmin = min(vmin, pv)
            vmax = max(vmax, pv)
        if umax < -1.0 or vmax < -1.0 or umin > width or vmin > height:
            continue
        # signed area; make the polygon counter-clockwise in (u, v)
        area = 0.0
        for k in range(m):
            k1 = (k + 1) % m
            area += poly[f, k, 0] * poly[f, k1, 1] - poly[f, k1, 0] * poly[f, k, 1]
        if not abs(area) > 1e-12:
            continue
        if area < 0.0:
            for k in range(m // 2):
                for j in range(2):
                    tmp = poly[f, k, j]
                    poly[f, k, j] = poly[f, m - 1 - k, j]
                    poly[f, m - 1 - k, j] = tmp
        ax = pts[1, 0] - pts[0, 0]
        ay = pts[1, 1] - pts[0, 1]
        az = pts[1, 2] - pts[0, 2]
        bx = pts[2, 0] - pts[0, 0]
        by = pts[2, 1] - pts[0, 1]
        bz = pts[2, 2] - pts[0, 2]
        nx = ay * bz - az * by
        ny = az * bx - ax * bz
        nz = ax * by - ay * bx
        ln = np.sqrt(nx * nx + ny * ny + nz * nz)
        if not ln > 0.0:
            continue
        nx /= ln
        ny /= ln
        nz /= ln
        c = nx * pts[0, 0] + ny * pts[0, 1] + nz * pts[0, 2]
        if c > 0.0:  # orient toward the camera: n . X = c < 0 on the plane
            nx, ny, nz, c = -nx, -ny, -nz, -c
        if c == 0.0:  # the plane passes through the camera: seen edge-on
            continue
        normal[f, 0] = nx
        normal[f, 1] = ny
        normal[f, 2] = nz
        offset[f] = c
        nvert[f] = m
        fbox[f, 0] = umin
        fbox[f, 1] = umax
        fbox[f, 2] = vmin
        fbox[f, 3] = vmax
    return normal, offset, poly, nvert, fbox


@nb.njit(cache=True)
def int_boxes(nvert, fbox, margin, width, height):  # pragma: no cover - compiled
    """Integer pixel boxes (inclusive) of the faces, grown by ``margin`` px; -1 rows if empty."""
    nf = nvert.shape[0]
    bbox = np.full((nf, 4), -1, dtype=np.int64)
    active = np.zeros(nf, dtype=np.int32)
    for f in range(nf):
        if nvert[f] == 0:
            continue
        u0 = max(int(np.ceil(fbox[f, 0] - margin - _EDGE_TOL)), 0)
        u1 = min(int(np.floor(fbox[f, 1] + margin + _EDGE_TOL)), width - 1)
        v0 = max(int(np.ceil(fbox[f, 2] - margin - _EDGE_TOL)), 0)
        v1 = min(int(np.floor(fbox[f, 3] + margin + _EDGE_TOL)), height - 1)
        if u0 > u1 or v0 > v1:
            continue
        bbox[f, 0] = u0
        bbox[f, 1] = u1
        bbox[f, 2] = v0
        bbox[f, 3] = v1
        active[f] = nvert[f]
    return active, bbox


@nb.njit(cache=True)
def bin_faces(nvert, bbox, tiles_u, tiles_v):  # pragma: no cover - compiled
    """CSR lists of the faces overlapping each tile, in face order."""
    ntiles = tiles_u * tiles_v
    count = np.zeros(ntiles + 1, dtype=np.int64)
    nf = nvert.shape[0]
    for f in range(nf):
        if nvert[f] == 0:
            continue
        for tv in range(bbox[f, 2] // TILE, bbox[f, 3] // TILE + 1):
            for tu in range(bbox[f, 0] // TILE, bbox[f, 1] // TILE + 1):
                count[tv * tiles_u + tu + 1] += 1
    for t in range(ntiles):
        count[t + 1] += count[t]
    fill = count[:-1].copy()
    items = np.empty(count[ntiles], dtype=np.int64)
    for f in range(nf):
        if nvert[f] == 0:
            continue
        for tv in range(bbox[f, 2] // TILE, bbox[f, 3] // TILE + 1):
            for tu in range(bbox[f, 0] // TILE, bbox[f, 1] // TILE + 1):
                t = tv * tiles_u + tu
                items[fill[t]] = f
                fill[t] += 1
    return count, items


@nb.njit(cache=True, parallel=True)
def raster_tiles(normal, offset, poly, nvert, bbox, start, items, tiles_u, tiles_v,
                 fx, fy, cx, cy, width, height, near, far, offsets, mask):  # pragma: no cover
    """Z-buffer every tile at the sample positions ``(u, v) + offsets[s]`` of the pixels where
    ``mask`` is True. Returns depth (H, W, S) (0 = no surface, NaN = not sampled) and face
    index (H, W, S) (-1)."""
    ns = offsets.shape[0]
    depth = np.zeros((height, width, ns))
    face = np.full((height, width, ns), -1, dtype=np.int32)
    ntiles = tiles_u * tiles_v
    for t in nb.prange(ntiles):
        tu = t % tiles_u
        tv = t // tiles_u
        tu0 = tu * TILE
        tv0 = tv * TILE
        tu1 = min(tu0 + TILE, width) - 1
        tv1 = min(tv0 + TILE, height) - 1
        edges = np.empty((4, 3))
        for i in range(start[t], start[t + 1]):
            f = items[i]
            m = nvert[f]
            u0 = max(bbox[f, 0], tu0)
            u1 = min(bbox[f, 1], tu1)
            v0 = max(bbox[f, 2], tv0)
            v1 = min(bbox[f, 3], tv1)
            nx = normal[f, 0]
            ny = normal[f, 1]
            nz = normal[f, 2]
            c = offset[f]
            # edge k: signed distance in pixels, e = A u + B v + C >= 0 inside
            for k in range(m):
                k1 = k + 1 if k + 1 < m else 0
                ax = poly[f, k, 0]
                ay = poly[f, k, 1]
                ex = poly[f, k1, 0] - ax
                ey = poly[f, k1, 1] - ay
                le = np.sqrt(ex * ex + ey * ey)
                if le == 0.0:  # repeated vertex after clipping: no constraint
                    edges[k, 0] = 0.0
                    edges[k, 1] = 0.0
                    edges[k, 2] = 0.0
                    continue
                edges[k, 0] = -ey / le
                edges[k, 1] = ex / le
                edges[k, 2] = (ey * ax - ex * ay) / le
            for v in range(v0, v1 + 1):
                for u in range(u0, u1 + 1):
                    if not mask[v, u]:
                        continue
                    for s in range(ns):
                        su = u + offsets[s, 0]
                        sv = v + offsets[s, 1]
                        inside = True
                        for k in range(m):
                            if edges[k, 0] * su + edges[k, 1] * sv + edges[k, 2] < -_EDGE_TOL:
                                inside = False
                                break
                        if not inside:
                            continue
                        den = nx * (su - cx) / fx + ny * (sv - cy) / fy + nz
                        if not den < 0.0:
                            continue
                        z = c / den
                        if z < near or z > far:
                            continue
                        old = depth[v, u, s]
                        if old == 0.0 or z < old:
                            depth[v, u, s] = z
                            face[v, u, s] = f
    for v in nb.prange(height):
        for u in range(width):
            if not mask[v, u]:
                for s in range(ns):
                    depth[v, u, s] = np.nan
    return depth, face
