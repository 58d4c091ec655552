/* Rasterising one projected triangle into a local z-buffer of TW x TH tile pixels.
 *
 * Vertices are (x_t, y_t, 1/z) in tile coordinates (x right, y down; pixel (i, j) is sampled
 * at its centre (i + 0.5, j + 0.5)), plus the range of pixel-centre columns and rows each
 * vertex lies between (vertex_span), so that the many triangles smaller than a tile pixel
 * are rejected with a few integer compares. Coverage uses edge functions E = A x + B y + C
 * whose coefficients are computed from the edge's endpoints in a canonical (lexicographic)
 * order and negated when the edge runs the other way, so the two triangles sharing an edge
 * see exactly opposite values; pixels exactly on an edge belong to the triangle for which
 * the edge is "top-left" (first non-zero of (A, B) positive), so shared edges are covered
 * once and never cracked. Depth is perspective-correct: 1/z is affine in screen space.
 * The z-buffer holds the int bit patterns of 1/z (positive floats, whose integer order is
 * their float order; 0 = background) and keeps the largest, i.e. the nearest surface, so
 * atomic_max works when WG > 1. Plain multiply-adds throughout: fma() is a slow library
 * call on some CPU back ends (PoCL).
 *
 * On a CPU (one work-item per particle) the same arithmetic runs in 8 vector lanes
 * (VECROW below): 8 triangles' candidate tests and set-ups at a time, then each
 * kept triangle's rows 8 pixels at a time; the z-buffer is bit-identical to the scalar
 * path's (tests/gpu/test_scorer.py) and the kernel 2x faster (BENCHMARKS.md, issue 13).
 */
#ifndef SWARMPOSE_RASTER_H
#define SWARMPOSE_RASTER_H

#include "include/util.h"

/* VECROW (the scorer passes it; 0 if not): rows drawn 8 pixels at a time (vector lanes), for a
 * plain z-buffer whose rows are whole 8-int blocks; score.cl's one-work-item path then also
 * scans and sets up the triangles 8 at a time (keep_candidates, raster_kept). */
#ifndef VECROW
#define VECROW 0
#endif
#if VECROW && (ZATOMIC || TW % 8)
#error "VECROW needs a plain z-buffer (ZATOMIC=0) and TW a multiple of 8"
#endif

typedef struct { float a, b, c; int top_left; } edge_t;

/* (first column, last column, first row, last row) of pixel centres >= / <= the vertex:
 * a triangle's box holds the centres min(first)..max(last). Clamped to [-1, TW] x [-1, TH]. */
inline short4 vertex_span(const float4 v)
{
    const float x = clampf(v.x - 0.5f, -1.0f, (float)TW);
    const float y = clampf(v.y - 0.5f, -1.0f, (float)TH);
    return (short4)((short)iceil(x), (short)ifloor(x), (short)iceil(y), (short)ifloor(y));
}

/* Edge p -> q, oriented so that the triangle's interior is positive (sign = +-1). */
inline edge_t edge_setup(const float2 p, const float2 q, const float sign)
{
    const bool swap = (q.x < p.x) || (q.x == p.x && q.y < p.y);
    const float2 s = swap ? q : p;
    const float2 t = swap ? p : q;
    const float flip = swap ? -sign : sign;
    edge_t e;
    e.a = flip * (s.y - t.y);
    e.b = flip * (t.x - s.x);
    e.c = flip * (s.x * t.y - s.y * t.x);
    e.top_left = (e.a > 0.0f) || (e.a == 0.0f && e.b > 0.0f);
    return e;
}

/* Branch-free: may the triangle cover a pixel centre (box not empty, in front of the near
 * plane, facing the camera when CULL)? The exact tests follow in raster_triangle. */
inline int triangle_candidate(const float4 p0, const float4 p1, const float4 p2,
                              const short4 s0, const short4 s1, const short4 s2)
{
    const int x0 = IMAX(IMIN(IMIN((int)s0.x, (int)s1.x), (int)s2.x), 0);
    const int x1 = IMIN(IMAX(IMAX((int)s0.y, (int)s1.y), (int)s2.y), TW - 1);
    const int y0 = IMAX(IMIN(IMIN((int)s0.z, (int)s1.z), (int)s2.z), 0);
    const int y1 = IMIN(IMAX(IMAX((int)s0.w, (int)s1.w), (int)s2.w), TH - 1);
    const float area = (p1.x - p0.x) * (p2.y - p0.y) - (p1.y - p0.y) * (p2.x - p0.x);
#if CULL
    const int facing = area < 0.0f;
#else
    const int facing = (area < 0.0f) | (area > 0.0f);  /* not degenerate, not NaN */
#endif
    return (x0 <= x1) & (y0 <= y1) & (p0.z > 0.0f) & (p1.z > 0.0f) & (p2.z > 0.0f) & facing;
}

/* Draw the pixel centres of the box [x0, x1] x [y0, y1] that the three edges (edge_setup)
 * cover into zbuf, at 1/z = p0z + dzdx (x - p0x) + dzdy (y - p0y). */
inline __attribute__((always_inline)) void raster_rows(__local int *zbuf, const int x0, const int x1, const int y0,
                                                       const int y1, const edge_t e0, const edge_t e1,
                                                       const edge_t e2, const float dzdx, const float dzdy,
                                                       const float p0x, const float p0y, const float p0z)
{
#if VECROW
    /* 8 pixels of a row at a time (vector lanes), over the aligned 8-pixel blocks the box
     * touches: the z-buffer rows start at multiples of 8 ints, so the loads and stores are
     * aligned; lanes outside [x0, x1] keep their old value */
    const int8 lane = (int8)(0, 1, 2, 3, 4, 5, 6, 7);
    const int xa = x0 & ~7;
    for (int y = y0; y <= y1; ++y) {
        const float py = (float)y + 0.5f;
        const float r0 = e0.b * py + e0.c, r1 = e1.b * py + e1.c, r2 = e2.b * py + e2.c;
        const float zrow = dzdy * (py - p0y) + p0z;
        for (int xb = xa; xb <= x1; xb += 8) {
            const int8 xi = (int8)(xb) + lane;
            const float8 px = convert_float8(xi) + 0.5f;
            const float8 v0 = e0.a * px + r0, v1 = e1.a * px + r1, v2 = e2.a * px + r2;
            const float8 iz = dzdx * (px - p0x) + zrow;
            const int8 inside = ((v0 > 0.0f) | ((v0 == 0.0f) & (int8)(-e0.top_left)))
                              & ((v1 > 0.0f) | ((v1 == 0.0f) & (int8)(-e1.top_left)))
                              & ((v2 > 0.0f) | ((v2 == 0.0f) & (int8)(-e2.top_left)))
                              & (iz > 0.0f) & (xi >= (int8)(x0)) & (xi <= (int8)(x1));
            __local int8 *zrow8 = (__local int8 *)(zbuf + y * TW + xb);
            const int8 old = *zrow8;
            const int8 zi = as_int8(iz);
            *zrow8 = (inside & (zi > old)) ? zi : old;
        }
    }
#else
    for (int y = y0; y <= y1; ++y) {
        const float py = (float)y + 0.5f;
        const float r0 = e0.b * py + e0.c, r1 = e1.b * py + e1.c, r2 = e2.b * py + e2.c;
        const float zrow = dzdy * (py - p0y) + p0z;
        for (int x = x0; x <= x1; ++x) {
            /* branch-free: all three edges, then one masked z-test */
            const float px = (float)x + 0.5f;
            const float v0 = e0.a * px + r0, v1 = e1.a * px + r1, v2 = e2.a * px + r2;
            const float iz = dzdx * (px - p0x) + zrow;
            const int inside = ((v0 > 0.0f) | ((v0 == 0.0f) & e0.top_left))
                             & ((v1 > 0.0f) | ((v1 == 0.0f) & e1.top_left))
                             & ((v2 > 0.0f) | ((v2 == 0.0f) & e2.top_left)) & (iz > 0.0f);
#if ZATOMIC
            if (inside)
                atomic_max(zbuf + y * TW + x, as_int(iz));
#else
            const int old = zbuf[y * TW + x];
            zbuf[y * TW + x] = inside ? IMAX(old, as_int(iz)) : old;
#endif
        }
    }
#endif
}

inline __attribute__((always_inline)) void raster_triangle(__local int *zbuf, const float4 p0, const float4 p1,
                                                           const float4 p2, const short4 s0, const short4 s1,
                                                           const short4 s2)
{
    const int x0 = IMAX(IMIN(IMIN((int)s0.x, (int)s1.x), (int)s2.x), 0);
    const int x1 = IMIN(IMAX(IMAX((int)s0.y, (int)s1.y), (int)s2.y), TW - 1);
    const int y0 = IMAX(IMIN(IMIN((int)s0.z, (int)s1.z), (int)s2.z), 0);
    const int y1 = IMIN(IMAX(IMAX((int)s0.w, (int)s1.w), (int)s2.w), TH - 1);
    if (x0 > x1 || y0 > y1)
        return;  /* no pixel centre inside the triangle's box */
    if (!(p0.z > 0.0f && p1.z > 0.0f && p2.z > 0.0f))
        return;  /* a vertex before the near plane, or NaN */
    const float area = (p1.x - p0.x) * (p2.y - p0.y) - (p1.y - p0.y) * (p2.x - p0.x);
#if CULL
    if (!(area < 0.0f))
        return;  /* back-facing (front faces have negative area in y-down tile coordinates) */
#else
    if (!(area < 0.0f || area > 0.0f))
        return;  /* degenerate or NaN */
#endif
    const float sign = area > 0.0f ? 1.0f : -1.0f;
    const edge_t e0 = edge_setup(p1.xy, p2.xy, sign);
    const edge_t e1 = edge_setup(p2.xy, p0.xy, sign);
    const edge_t e2 = edge_setup(p0.xy, p1.xy, sign);
    /* 1/z = p0.z + dzdx (x - p0.x) + dzdy (y - p0.y) */
    const float inv = 1.0f / area;
    const float dzdx = ((p1.z - p0.z) * (p2.y - p0.y) - (p2.z - p0.z) * (p1.y - p0.y)) * inv;
    const float dzdy = ((p2.z - p0.z) * (p1.x - p0.x) - (p1.z - p0.z) * (p2.x - p0.x)) * inv;
    raster_rows(zbuf, x0, x1, y0, y1, e0, e1, e2, dzdx, dzdy, p0.x, p0.y, p0.z);
}

#if VECROW
typedef union { float8 v; float s[8]; } float8_lanes;
typedef union { int8 v; int s[8]; } int8_lanes;

/* Lane S of the float8 vertex coordinates (ax .. cz) of a triangle TRI (its int4 vertex
 * indices), from the projected vertices. */
#define GATHER_TRIANGLE(TRI, S)                                                                      \
        {                                                                                           \
            const int4 tri = TRI;                                                                   \
            const float4 va = lverts[tri.x], vb = lverts[tri.y], vc = lverts[tri.z];                \
            ax.S = va.x; ay.S = va.y; az.S = va.z; bx.S = vb.x; by.S = vb.y; bz.S = vb.z;           \
            cx.S = vc.x; cy.S = vc.y; cz.S = vc.z;                                                  \
        }

/* The box of pixel centres (x0, x1, y0, y1: first and last column and row) of 8 triangles,
 * clipped to the tile: the union of their vertices' vertex_span, computed from the extremes
 * of the coordinates (ceil, floor and the clamp are monotonic, so they commute with min/max). */
#define TRIANGLE_BOXES(ax, ay, bx, by, cx, cy, x0, x1, y0, y1)                                       \
    const int8 x0 = IMAX(iceil8(clampf8(IMIN(IMIN(ax, bx), cx) - 0.5f, -1.0f, (float)TW)), (int8)(0));        \
    const int8 x1 = IMIN(ifloor8(clampf8(IMAX(IMAX(ax, bx), cx) - 0.5f, -1.0f, (float)TW)), (int8)(TW - 1));  \
    const int8 y0 = IMAX(iceil8(clampf8(IMIN(IMIN(ay, by), cy) - 0.5f, -1.0f, (float)TH)), (int8)(0));        \
    const int8 y1 = IMIN(ifloor8(clampf8(IMAX(IMAX(ay, by), cy) - 0.5f, -1.0f, (float)TH)), (int8)(TH - 1));

/* triangle_candidate over all NF triangles, 8 at a time in vector lanes: the indices of those
 * that may cover a pixel centre go to lkeep (in triangle order); returns how many. */
inline int keep_candidates(__local const float4 *lverts, __global const int4 *tris, __local int *lkeep)
{
    const int8 lane = (int8)(0, 1, 2, 3, 4, 5, 6, 7);
    int kept = 0;
    for (int t0 = 0; t0 < NF; t0 += 8) {
        float8 ax, ay, az, bx, by, bz, cx, cy, cz;
        GATHER_TRIANGLE(tris[IMIN(t0 + 0, NF - 1)], s0) GATHER_TRIANGLE(tris[IMIN(t0 + 1, NF - 1)], s1)
        GATHER_TRIANGLE(tris[IMIN(t0 + 2, NF - 1)], s2) GATHER_TRIANGLE(tris[IMIN(t0 + 3, NF - 1)], s3)
        GATHER_TRIANGLE(tris[IMIN(t0 + 4, NF - 1)], s4) GATHER_TRIANGLE(tris[IMIN(t0 + 5, NF - 1)], s5)
        GATHER_TRIANGLE(tris[IMIN(t0 + 6, NF - 1)], s6) GATHER_TRIANGLE(tris[IMIN(t0 + 7, NF - 1)], s7)
        TRIANGLE_BOXES(ax, ay, bx, by, cx, cy, bx0, bx1, by0, by1)
        const float8 area = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax);
#if CULL
        const int8 facing = area < 0.0f;
#else
        const int8 facing = (area < 0.0f) | (area > 0.0f);
#endif
        int8_lanes ok;
        ok.v = (bx0 <= bx1) & (by0 <= by1) & (az > 0.0f) & (bz > 0.0f) & (cz > 0.0f) & facing
             & ((int8)(t0) + lane < (int8)(NF));
        for (int l = 0; l < 8; ++l) {
            lkeep[kept] = t0 + l;
            kept -= ok.s[l];  /* -1 where kept */
        }
    }
    return kept;
}

/* edge_setup for 8 edges at once (lane l: p -> q of triangle l): the same arithmetic, so a
 * triangle's edges are bit-identical to those of the scalar path */
inline void edge_setup8(const float8 px, const float8 py, const float8 qx, const float8 qy, const float8 sign,
                        float8_lanes *a, float8_lanes *b, float8_lanes *c, int8_lanes *top_left)
{
    const int8 swap = (qx < px) | ((qx == px) & (qy < py));
    const float8 sx = swap ? qx : px, sy = swap ? qy : py;
    const float8 tx = swap ? px : qx, ty = swap ? py : qy;
    const float8 flip = swap ? -sign : sign;
    a->v = flip * (sy - ty);
    b->v = flip * (tx - sx);
    c->v = flip * (sx * ty - sy * tx);
    top_left->v = -((a->v > 0.0f) | ((a->v == 0.0f) & (b->v > 0.0f)));  /* 1 or 0 */
}

/* Set up 8 triangles at once in vector lanes (edges, depth plane; the same arithmetic as
 * raster_triangle, so bit-identical) and draw the rows of each lane whose draw mask is set
 * (-1). Vertices: (x, y) tile pixels and 1/z of a, b, c per lane; box: pixel centres. */
inline __attribute__((always_inline)) void draw8(__local int *zbuf, const float8 ax, const float8 ay,
                                                 const float8 az, const float8 bx, const float8 by,
                                                 const float8 bz, const float8 cx, const float8 cy,
                                                 const float8 cz, const int8 bx0, const int8 bx1,
                                                 const int8 by0, const int8 by1, const int8 draw)
{
    const float8 area = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax);
    const float8 sign = area > 0.0f ? (float8)(1.0f) : (float8)(-1.0f);
    float8_lanes a0, b0, c0, a1, b1, c1, a2, b2, c2, dzdx, dzdy, p0x, p0y, p0z;
    int8_lanes t0, t1, t2, x0, x1, y0, y1, on;
    edge_setup8(bx, by, cx, cy, sign, &a0, &b0, &c0, &t0);
    edge_setup8(cx, cy, ax, ay, sign, &a1, &b1, &c1, &t1);
    edge_setup8(ax, ay, bx, by, sign, &a2, &b2, &c2, &t2);
    const float8 inv = 1.0f / area;
    dzdx.v = ((bz - az) * (cy - ay) - (cz - az) * (by - ay)) * inv;
    dzdy.v = ((cz - az) * (bx - ax) - (bz - az) * (cx - ax)) * inv;
    p0x.v = ax;
    p0y.v = ay;
    p0z.v = az;
    x0.v = bx0;
    x1.v = bx1;
    y0.v = by0;
    y1.v = by1;
    on.v = draw;
    for (int l = 0; l < 8; ++l) {
        if (!on.s[l])
            continue;
        edge_t e0, e1, e2;
        e0.a = a0.s[l]; e0.b = b0.s[l]; e0.c = c0.s[l]; e0.top_left = t0.s[l];
        e1.a = a1.s[l]; e1.b = b1.s[l]; e1.c = c1.s[l]; e1.top_left = t1.s[l];
        e2.a = a2.s[l]; e2.b = b2.s[l]; e2.c = c2.s[l]; e2.top_left = t2.s[l];
        raster_rows(zbuf, x0.s[l], x1.s[l], y0.s[l], y1.s[l], e0, e1, e2, dzdx.s[l], dzdy.s[l], p0x.s[l], p0y.s[l],
                    p0z.s[l]);
    }
}

/* Draw the kept triangles lkeep[0..kept) (each passed triangle_candidate), 8 at a time
 * (draw8); the last group's unused lanes repeat its last triangle and are not drawn. */
inline void raster_kept(__local int *zbuf, __local const float4 *lverts, __global const int4 *tris,
                        __local const int *lkeep, const int kept)
{
    const int8 lane = (int8)(0, 1, 2, 3, 4, 5, 6, 7);
    for (int k0 = 0; k0 < kept; k0 += 8) {
        float8 ax, ay, az, bx, by, bz, cx, cy, cz;
        GATHER_TRIANGLE(tris[lkeep[IMIN(k0 + 0, kept - 1)]], s0) GATHER_TRIANGLE(tris[lkeep[IMIN(k0 + 1, kept - 1)]], s1)
        GATHER_TRIANGLE(tris[lkeep[IMIN(k0 + 2, kept - 1)]], s2) GATHER_TRIANGLE(tris[lkeep[IMIN(k0 + 3, kept - 1)]], s3)
        GATHER_TRIANGLE(tris[lkeep[IMIN(k0 + 4, kept - 1)]], s4) GATHER_TRIANGLE(tris[lkeep[IMIN(k0 + 5, kept - 1)]], s5)
        GATHER_TRIANGLE(tris[lkeep[IMIN(k0 + 6, kept - 1)]], s6) GATHER_TRIANGLE(tris[lkeep[IMIN(k0 + 7, kept - 1)]], s7)
        TRIANGLE_BOXES(ax, ay, bx, by, cx, cy, bx0, bx1, by0, by1)
        draw8(zbuf, ax, ay, az, bx, by, bz, cx, cy, cz, bx0, bx1, by0, by1, lane < (int8)(kept - k0));
    }
}
#endif

#endif
