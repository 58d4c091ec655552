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
 */
#ifndef SWARMPOSE_RASTER_H
#define SWARMPOSE_RASTER_H

#include "include/util.h"

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

inline __attribute__((always_inline)) void raster_triangle(__local int *zbuf, const float4 p0, const float4 p1, const float4 p2,
                            const short4 s0, const short4 s1, const short4 s2)
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

    for (int y = y0; y <= y1; ++y) {
        const float py = (float)y + 0.5f;
        const float r0 = e0.b * py + e0.c, r1 = e1.b * py + e1.c, r2 = e2.b * py + e2.c;
        const float zrow = dzdy * (py - p0.y) + p0.z;
        for (int x = x0; x <= x1; ++x) {
            /* branch-free: all three edges, then one masked z-test */
            const float px = (float)x + 0.5f;
            const float v0 = e0.a * px + r0, v1 = e1.a * px + r1, v2 = e2.a * px + r2;
            const float iz = dzdx * (px - p0.x) + zrow;
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
}

#endif
