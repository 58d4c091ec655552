/* The particle scorer: one launch per PSO generation, one work-group per particle.
 *
 * Compile-time sizes (-D): NV vertices, NF triangles, NB bones, TW x TH tile pixels, WG
 * work-items per group (1 on CPUs: the z-buffer is then plain, not atomic), ZATOMIC (use
 * atomic_max on the local z-buffer; required when WG > 1), CULL (skip back faces: exact for
 * closed meshes seen from outside), ZNEAR (m; triangles with a vertex nearer are skipped),
 * WRITE_TILES (also write each particle's rendered depth tile and, with FK, its bone
 * transforms, for tests), FK (the inputs are
 * poses, P x POSE_DIM, and the kernel computes the bone transforms itself, include/fk.h, with NJ
 * tracking joints; it also writes the NPT named points of every particle; without FK the
 * inputs are bone transforms, P x NB x 3 x 4, and the FK tables and points are unused).
 *
 * For particle p: (FK) its bone transforms and named points from its pose, and from those the
 * joint and penetration terms (include/joint_term.h); unless render is 0
 * (a joint-term-only objective: counts and sums are then 0), skin the rest mesh with the NB
 * bone transforms (LBS, 4 influences), project
 * into the tile, rasterise a z-buffer (of 1/z, 1/m; 0 = background) and reduce over
 * the tile pixels with an observation d_o > 0:
 * Results, one float8 per particle: (sum, counts.x, .y, .z, .w, E_J2D, E_J3D, E_P), the counts as
 * exact floats (tiles hold fewer than 2^24 pixels), so that one read returns everything:
 *   sum          = sum of min(|d_h - d_o|, T), where a pixel the model does not cover has
 *                  d_h = 0 and so contributes min(d_o, T) (= T for any d_o >= T);
 *   counts.x     = observed pixels (d_o > 0), .y = rendered pixels (whole tile),
 *   counts.z     = rendered and observed, .w = rendered, observed and |d_h - d_o| < T.
 */
#include "include/skin.h"
#include "include/raster.h"
#if FK
#include "include/fk.h"
#include "include/joint_term.h"
#endif

#define NPIX (TW * TH)
#define BACKGROUND 0 /* bits of 1/z = 0: nothing rendered */

#if WG > 1 && !ZATOMIC
#error "WG > 1 needs ZATOMIC=1"
#endif

inline void reduce_pixel(const int zi, const float d_o, const float threshold, float *sum, int4 *cnt)
{
    const bool rendered = zi != BACKGROUND;
    const float d_h = rendered ? 1.0f / as_float(zi) : 0.0f;
    cnt->y += rendered;
    if (d_o > 0.0f) {
        const float diff = d_h > d_o ? d_h - d_o : d_o - d_h;
        *sum += diff < threshold ? diff : threshold;
        cnt->x += 1;
        cnt->z += rendered;
        cnt->w += rendered && diff < threshold;
    }
}

/* The depth term's sum and counts into the particle's results (its first five floats). */
inline void store_depth_term(__global float *results, const int p, const float sum, const int4 cnt)
{
    __global float *r = results + 8 * p;
    r[0] = sum;
    r[1] = (float)cnt.x;
    r[2] = (float)cnt.y;
    r[3] = (float)cnt.z;
    r[4] = (float)cnt.w;
}

inline int hsum8(const int8 v)
{
    const int4 a = v.lo + v.hi;
    return a.x + a.y + a.z + a.w;
}

__kernel __attribute__((reqd_work_group_size(WG, 1, 1)))
void score_particles(__global const float *hyp,       /* FK: P x POSE_DIM poses; else P x NB x 12, camera frame */
                     __global const float4 *steps,    /* FK tables (include/fk.h) */
                     __global const int2 *links,
                     __global const float4 *bone_data,
                     __global const int *point_bone,  /* NPT named points: bone, */
                     __global const float4 *point_rest, /* rest position (x, y, z, 0) body frame, m */
                     __global const float4 *rest,     /* NV (x, y, z, 0) body frame, m */
                     __global const int4 *skin_idx,   /* NV bone indices */
                     __global const float4 *skin_w,   /* NV weights, sum 1 */
                     __global const int4 *tris,       /* NF (a, b, c, 0) */
                     __global const float *obs,       /* TH x TW observed depth, m, 0 = none */
                     const float4 proj,               /* (ax, bx, ay, by) camera -> tile */
                     const float threshold,           /* T, m */
                     const int render,                /* 0: FK, points and terms only */
                     __global const float4 *tgt2d,    /* the joint targets (include/joint_term.h) */
                     __global const float4 *tgt3d,
                     __global const int2 *pairs,
                     __global const int *pen,
                     const int nt,
                     const int npair,
                     const int with_joints,
                     const float4 cam,
                     const float4 scal,
                     __global float *results,         /* P x 8 (see above) */
                     __global float4 *points,         /* P x NPT camera frame, m (FK only) */
                     __global float *tiles,           /* P x TH x TW if WRITE_TILES, else unused */
                     __global float4 *bones_out)      /* P x NB x 3 rows [R | t] if WRITE_TILES and FK */
{
    __local float4 lbones[NB * 3];
    __local float4 lverts[NV];
#if !VECROW
    __local short4 lspans[NV];
#endif
    __local int zbuf[NPIX] __attribute__((aligned(32)));
    const int p = get_group_id(0);
    const int lid = get_local_id(0);

#if FK
    __local float4 ljoint_q[NJ];
    __local float4 lframe_q[NB];
    __local float4 lpoints[NPT];
    if (lid == 0)
        forward_kinematics(hyp + p * POSE_DIM, steps, links, bone_data, ljoint_q, lframe_q, lbones);
    barrier(CLK_LOCAL_MEM_FENCE);
    for (int i = lid; i < NPT; i += WG) {
        const float4 q = (float4)(affine_apply(lbones + 3 * point_bone[i], point_rest[i].xyz), 0.0f);
        lpoints[i] = q;
        points[p * NPT + i] = q;
    }
    barrier(CLK_LOCAL_MEM_FENCE);
    if (lid == 0) {
        const float4 t = joint_terms(lpoints, tgt2d, tgt3d, pairs, nt, npair, cam, scal, pen, with_joints);
        results[8 * p + 5] = t.x;
        results[8 * p + 6] = t.y;
        results[8 * p + 7] = t.z;
    }
#if WRITE_TILES
    for (int i = lid; i < NB * 3; i += WG)
        bones_out[p * NB * 3 + i] = lbones[i];
#endif
    if (!render) {
        if (lid == 0) {
            store_depth_term(results, p, 0.0f, (int4)(0));
        }
        return;
    }
#else
    for (int i = lid; i < NB * 3; i += WG)
        lbones[i] = ((__global const float4 *)hyp)[p * NB * 3 + i];
#endif
    for (int i = lid; i < NPIX; i += WG)
        zbuf[i] = BACKGROUND;
    barrier(CLK_LOCAL_MEM_FENCE);

    for (int v = lid; v < NV; v += WG) {
        const float4 q = project_tile(skin_lbs(lbones, rest[v], skin_idx[v], skin_w[v]), proj);
        lverts[v] = q;
#if !VECROW
        lspans[v] = vertex_span(q);
#endif
    }
    barrier(CLK_LOCAL_MEM_FENCE);

    /* one work-item: two passes, a branch-free scan keeps the triangles that may cover a pixel
     * centre (on a CPU most of them are smaller than a tile pixel), then only those are drawn;
     * with VECROW (which implies WG == 1: it needs ZATOMIC=0) 8 triangles at a time */
#if VECROW
    __local int lkeep[NF + 8];
    const int kept = keep_candidates(lverts, tris, lkeep);
    raster_kept(zbuf, lverts, tris, lkeep, kept);
#elif WG == 1
    __local int lkeep[NF + 8];
    int kept = 0;
    for (int t = 0; t < NF; ++t) {
        const int4 tri = tris[t];
        lkeep[kept] = t;
        kept += triangle_candidate(lverts[tri.x], lverts[tri.y], lverts[tri.z], lspans[tri.x], lspans[tri.y],
                                   lspans[tri.z]);
    }
    for (int k = 0; k < kept; ++k) {
        const int4 tri = tris[lkeep[k]];
        raster_triangle(zbuf, lverts[tri.x], lverts[tri.y], lverts[tri.z], lspans[tri.x], lspans[tri.y],
                        lspans[tri.z]);
    }
#else
    for (int t = lid; t < NF; t += WG) {
        const int4 tri = tris[t];
        raster_triangle(zbuf, lverts[tri.x], lverts[tri.y], lverts[tri.z], lspans[tri.x], lspans[tri.y],
                        lspans[tri.z]);
    }
#endif
    barrier(CLK_LOCAL_MEM_FENCE);

#if WG == 1 && TW % 8 == 0
    /* 8 pixels at a time (vector lanes), one partial float8 per row */
    float8 total = (float8)(0.0f);
    int8 c_obs = (int8)(0), c_ren = (int8)(0), c_both = (int8)(0), c_close = (int8)(0);
    for (int y = 0; y < TH; ++y) {
        float8 row = (float8)(0.0f);
        for (int x = 0; x < TW; x += 8) {
            const int8 zi = *(__local const int8 *)(zbuf + y * TW + x);
            const float8 d_o = *(__global const float8 *)(obs + y * TW + x);
            const int8 o = d_o > 0.0f;  /* -1 where true */
            const int8 r = zi != BACKGROUND;
            const float8 d_h = r ? 1.0f / as_float8(zi) : (float8)(0.0f);
            const float8 diff = d_h > d_o ? d_h - d_o : d_o - d_h;
            row += o ? (diff < threshold ? diff : (float8)(threshold)) : (float8)(0.0f);
            c_obs -= o;
            c_ren -= r;
            c_both -= o & r;
            c_close -= o & r & (diff < threshold);
        }
        total += row;
    }
    store_depth_term(results, p,
                     ((total.s0 + total.s1) + (total.s2 + total.s3)) + ((total.s4 + total.s5) + (total.s6 + total.s7)),
                     (int4)(hsum8(c_obs), hsum8(c_ren), hsum8(c_both), hsum8(c_close)));
#elif WG == 1
    float total = 0.0f;
    int4 cnt = (int4)(0);
    for (int y = 0; y < TH; ++y) {  /* per-row partial sums keep float32 rounding small */
        float row = 0.0f;
        for (int x = 0; x < TW; ++x)
            reduce_pixel(zbuf[y * TW + x], obs[y * TW + x], threshold, &row, &cnt);
        total += row;
    }
    store_depth_term(results, p, total, cnt);
#else
    __local float lsum[WG];
    __local int4 lcnt[WG];
    float part = 0.0f;
    int4 cnt = (int4)(0);
    for (int i = lid; i < NPIX; i += WG)
        reduce_pixel(zbuf[i], obs[i], threshold, &part, &cnt);
    lsum[lid] = part;
    lcnt[lid] = cnt;
    barrier(CLK_LOCAL_MEM_FENCE);
    for (int s = WG / 2; s > 0; s >>= 1) {  /* WG is a power of two */
        if (lid < s) {
            lsum[lid] += lsum[lid + s];
            lcnt[lid] += lcnt[lid + s];
        }
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    if (lid == 0) {
        store_depth_term(results, p, lsum[0], lcnt[0]);
    }
#endif

#if WRITE_TILES
    for (int i = lid; i < NPIX; i += WG)
        tiles[p * NPIX + i] = zbuf[i] == BACKGROUND ? 0.0f : 1.0f / as_float(zbuf[i]);
#endif
}
