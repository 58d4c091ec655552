/* The objective's joint and penetration terms of one particle from its named points, on the
 * device (swarmpose.tracking.objective holds the numpy oracle and the definitions).
 *
 * Targets (per frame, NT <= NPT of them): tgt2d[t] = (detected x, y px; weight; index of the
 * model point, as a float), tgt3d[t] = (lifted x, y, z m; 1 if lifted, 0 if not);
 * pairs[k] = (target of a left point, target of its right twin), NPAIR of them.
 * terms = (cam fx, fy, cx, cy), scal = (swap cost px; 1/sum of 2D weights; 1/sum of 3D
 * weights or 0; torso radius m); pen = model indices of the 4 arm points, 2 hips, 2 shoulders.
 * Writes (E_J2D px, E_J3D mm, E_P cm, 0).
 */
#ifndef SWARMPOSE_JOINT_TERM_H
#define SWARMPOSE_JOINT_TERM_H

#include "include/util.h"

inline float2 project_point(const float4 p, const float4 cam)
{
    const float z = p.z > 1e-3f ? p.z : 1e-3f;  /* a point behind the camera must not flip sides */
    return (float2)(p.x / z * cam.x + cam.z, p.y / z * cam.y + cam.w);
}

inline float dist2(const float2 a, const float2 b)
{
    const float2 d = a - b;
    return sqrt(d.x * d.x + d.y * d.y);
}

inline float dist3(const float4 a, const float4 b)
{
    const float4 d = a - b;
    return sqrt(d.x * d.x + d.y * d.y + d.z * d.z);
}

inline float4 joint_terms(__local const float4 *pts, __global const float4 *tgt2d, __global const float4 *tgt3d,
                          __global const int2 *pairs, const int nt, const int npair, const float4 cam,
                          const float4 scal, __global const int *pen, const int with_joints)
{
    float e2 = 0.0f, e3 = 0.0f;
    if (with_joints) {
        int match[NPT];
        for (int t = 0; t < nt; ++t)
            match[t] = t;
        for (int k = 0; k < npair; ++k) {  /* each detected pair straight or crossed, crossed at a cost */
            const int l = pairs[k].x, r = pairs[k].y;
            const float4 tl = tgt2d[l], tr = tgt2d[r];
            const float2 pl = project_point(pts[(int)tl.w], cam), pr = project_point(pts[(int)tr.w], cam);
            const float straight = dist2(pl, tl.xy) + dist2(pr, tr.xy);
            const float crossed = dist2(pr, tl.xy) + dist2(pl, tr.xy) + 2.0f * scal.x;
            if (crossed < straight) {
                match[l] = r;
                match[r] = l;
            }
        }
        for (int t = 0; t < nt; ++t) {
            const float4 tt = tgt2d[t];
            const float4 p = pts[(int)tgt2d[match[t]].w];
            e2 += tt.z * (dist2(project_point(p, cam), tt.xy) + (match[t] != t ? scal.x : 0.0f));
            const float4 l3 = tgt3d[t];
            if (l3.w > 0.0f)
                e3 += tt.z * dist3(p, l3);
        }
        e2 *= scal.y;
        e3 *= 1000.0f * scal.z;
    }
    /* elbows and wrists inside the torso's core: a capsule from the hips' middle to the shoulders' */
    const float4 hip = 0.5f * (pts[pen[4]] + pts[pen[5]]);
    const float4 axis = 0.5f * (pts[pen[6]] + pts[pen[7]]) - hip;
    const float len2 = axis.x * axis.x + axis.y * axis.y + axis.z * axis.z;
    float ep = 0.0f;
    for (int a = 0; a < 4; ++a) {
        const float4 d = pts[pen[a]] - hip;
        const float along = clampf((d.x * axis.x + d.y * axis.y + d.z * axis.z) / (len2 > 1e-12f ? len2 : 1e-12f),
                                   0.0f, 1.0f);
        const float depth = scal.w - dist3(pts[pen[a]], hip + along * axis);
        ep += depth > 0.0f ? depth : 0.0f;
    }
    return (float4)(e2, e3, 100.0f * ep, 0.0f);
}

#endif
