"""Compiled kernels of the z-buffer renderer (numba, cached).

Each triangle is clipped against the near plane ``z = near`` (Sutherland-Hodgman, giving a
convex polygon of at most four vertices), projected, and binned into square screen tiles
(each tile's z-buffer stays in cache); inside a tile faces are visited in index order.
Single-threaded on purpose: on the 2-core target machine, shared with other work, numba's
parallel threads were 2-4x slower than one thread (docs/benchmarks.md, section 7).

A pixel is covered when its integer position lies inside the projected polygon (edges
inclusive, with a 1e-9 pixel tolerance so shared edges never leave cracks); its depth is
the exact intersection of its ray with the plane of the triangle, ``z = c / (n . r)`` with
``r = ((u - cx) / fx, (v - cy) / fy, 1)``. On equal depth the lower face index wins.
"""

from __future__ import annotations

import numba as nb
import numpy as np

TILE = 32
_EDGE_TOL = 1e-9  # pixels


@nb.njit(cache=True)
def setup_faces(vc, faces, fx, fy, cx, cy, width, height, near):  # pragma: no cover - compiled
    """Per face: camera-facing unit normal, plane offset, the edge equations of the projected
    clipped polygon (counter-clockwise; ``A u + B v + C`` is the signed distance in pixels,
    >= 0 inside) and its float bounding box (umin, umax, vmin, vmax). ``nvert`` (the polygon's
    vertex count) is 0 for faces not drawn."""
    nf = faces.shape[0]
    # only rows of faces with nvert > 0 are ever read: no need to clear the others
    normal = np.empty((nf, 3))
    offset = np.empty(nf)
    edges = np.empty((nf, 4, 3))
    nvert = np.zeros(nf, dtype=np.int32)
    fbox = np.empty((nf, 4))
    poly = np.empty((nf, 4, 2))  # scratch: clipped, projected polygon
    for f in range(nf):
        i0 = faces[f, 0]
        i1 = faces[f, 1]
        i2 = faces[f, 2]
        z0 = vc[i0, 2]
        z1 = vc[i1, 2]
        z2 = vc[i2, 2]
        if z0 < near and z1 < near and z2 < near:
            continue
        # frustum side planes through the camera centre (one pixel of margin): a triangle
        # with all three vertices outside one of these half-spaces cannot be seen
        x0 = fx * vc[i0, 0]
        x1 = fx * vc[i1, 0]
        x2 = fx * vc[i2, 0]
        if x0 + (cx + 1.0) * z0 < 0.0 and x1 + (cx + 1.0) * z1 < 0.0 and x2 + (cx + 1.0) * z2 < 0.0:
            continue
        if x0 + (cx - width) * z0 > 0.0 and x1 + (cx - width) * z1 > 0.0 and x2 + (cx - width) * z2 > 0.0:
            continue
        y0 = fy * vc[i0, 1]
        y1 = fy * vc[i1, 1]
        y2 = fy * vc[i2, 1]
        if y0 + (cy + 1.0) * z0 < 0.0 and y1 + (cy + 1.0) * z1 < 0.0 and y2 + (cy + 1.0) * z2 < 0.0:
            continue
        if y0 + (cy - height) * z0 > 0.0 and y1 + (cy - height) * z1 > 0.0 and y2 + (cy - height) * z2 > 0.0:
            continue
        # plane first (cheap) and the edge-on test
        ax = vc[i1, 0] - vc[i0, 0]
        ay = vc[i1, 1] - vc[i0, 1]
        az = z1 - z0
        bx = vc[i2, 0] - vc[i0, 0]
        by = vc[i2, 1] - vc[i0, 1]
        bz = z2 - z0
        nx = ay * bz - az * by
        ny = az * bx - ax * bz
        nz = ax * by - ay * bx
        ln = np.sqrt(nx * nx + ny * ny + nz * nz)
        if not ln > 0.0:
            continue
        nx /= ln
        ny /= ln
        nz /= ln
        c = nx * vc[i0, 0] + ny * vc[i0, 1] + nz * z0
        if c > 0.0:  # orient toward the camera: n . X = c < 0 on the plane
            nx = -nx
            ny = -ny
            nz = -nz
            c = -c
        if c == 0.0:  # the plane passes through the camera: seen edge-on
            continue
        # clip against z >= near (Sutherland-Hodgman), project
        pu = poly[f, :, 0]
        pv = poly[f, :, 1]
        m = 0
        for k in range(3):
            ia = faces[f, k]
            ib = faces[f, (k + 1) % 3]
            xa, ya, za = vc[ia, 0], vc[ia, 1], vc[ia, 2]
            xb, yb, zb = vc[ib, 0], vc[ib, 1], vc[ib, 2]
            if za >= near:
                pu[m] = fx * xa / za + cx
                pv[m] = fy * ya / za + cy
                m += 1
            if (za >= near) != (zb >= near):
                t = (near - za) / (zb - za)
                pu[m] = fx * (xa + t * (xb - xa)) / near + cx
                pv[m] = fy * (ya + t * (yb - ya)) / near + cy
                m += 1
        umin = pu[0]
        umax = pu[0]
        vmin = pv[0]
        vmax = pv[0]
        for k in range(1, m):
            umin = min(umin, pu[k])
            umax = max(umax, pu[k])
            vmin = min(vmin, pv[k])
            vmax = max(vmax, pv[k])
        if umax < -1.0 or vmax < -1.0 or umin > width or vmin > height:
            continue
        area = 0.0
        for k in range(m):
            k1 = (k + 1) % m
            area += pu[k] * pv[k1] - pu[k1] * pv[k]
        if not abs(area) > 1e-12:
            continue
        sgn = 1.0 if area > 0.0 else -1.0
        for k in range(m):
            k1 = (k + 1) % m
            ex = pu[k1] - pu[k]
            ey = pv[k1] - pv[k]
            le = np.sqrt(ex * ex + ey * ey)
            if le == 0.0:  # repeated vertex after clipping: no constraint
                edges[f, k, 0] = 0.0
                edges[f, k, 1] = 0.0
                edges[f, k, 2] = 0.0
                continue
            edges[f, k, 0] = -sgn * ey / le
            edges[f, k, 1] = sgn * ex / le
            edges[f, k, 2] = sgn * (ey * pu[k] - ex * pv[k]) / le
        normal[f, 0] = nx
        normal[f, 1] = ny
        normal[f, 2] = nz
        offset[f] = c
        nvert[f] = m
        fbox[f, 0] = umin
        fbox[f, 1] = umax
        fbox[f, 2] = vmin
        fbox[f, 3] = vmax
    return normal, offset, edges, nvert, fbox


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


@nb.njit(cache=True)
def raster_tiles(faces, bins, cam, image, offsets, mask):  # pragma: no cover
    """Z-buffer every tile at the sample positions ``(u, v) + offsets[s]`` of the pixels where
    ``mask`` is True. Returns depth (H, W, S) (0 = no surface, NaN = not sampled) and face
    index (H, W, S) (-1).

    ``faces = (normal, offset, edges, nvert, bbox)`` (:func:`setup_faces`, :func:`int_boxes`),
    ``bins = (start, items, tiles_u, tiles_v)`` (:func:`bin_faces`), ``cam = (fx, fy, cx,
    cy)``, ``image = (width, height, near, far)``.
    """
    normal, offset, edges, nvert, bbox = faces
    start, items, tiles_u, tiles_v = bins
    fx, fy, cx, cy = cam
    width, height, near, far = image
    ns = offsets.shape[0]
    depth = np.zeros((height, width, ns))
    face = np.full((height, width, ns), -1, dtype=np.int32)
    ntiles = tiles_u * tiles_v
    for t in range(ntiles):
        tu = t % tiles_u
        tv = t // tiles_u
        tu0 = tu * TILE
        tv0 = tv * TILE
        tu1 = min(tu0 + TILE, width) - 1
        tv1 = min(tv0 + TILE, height) - 1
        for i in range(start[t], start[t + 1]):
            f = items[i]
            m = nvert[f]
            u0 = max(bbox[f, 0], tu0)
            u1 = min(bbox[f, 1], tu1)
            v0 = max(bbox[f, 2], tv0)
            v1 = min(bbox[f, 3], tv1)
            nx = normal[f, 0] / fx
            ny = normal[f, 1] / fy
            n0 = normal[f, 2] - nx * cx - ny * cy
            c = offset[f]
            for v in range(v0, v1 + 1):
                for u in range(u0, u1 + 1):
                    if not mask[v, u]:
                        continue
                    for s in range(ns):
                        su = u + offsets[s, 0]
                        sv = v + offsets[s, 1]
                        inside = True
                        for k in range(m):
                            if edges[f, k, 0] * su + edges[f, k, 1] * sv + edges[f, k, 2] < -_EDGE_TOL:
                                inside = False
                                break
                        if not inside:
                            continue
                        den = nx * su + ny * sv + n0
                        if not den < 0.0:
                            continue
                        z = c / den
                        if z < near or z > far:
                            continue
                        old = depth[v, u, s]
                        if old == 0.0 or z < old:
                            depth[v, u, s] = z
                            face[v, u, s] = f
    for v in range(height):
        for u in range(width):
            if not mask[v, u]:
                for s in range(ns):
                    depth[v, u, s] = np.nan
    return depth, face


@nb.njit(cache=True)
def gather_normals(face, normal):  # pragma: no cover - compiled
    """(H, W, 3) normals of the faces in ``face`` (H, W); NaN where ``face`` < 0."""
    h, w = face.shape
    out = np.empty((h, w, 3))
    for v in range(h):
        for u in range(w):
            f = face[v, u]
            for j in range(3):
                out[v, u, j] = normal[f, j] + 0.0 if f >= 0 else np.nan
    return out
