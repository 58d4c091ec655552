/* Linear blend skinning and pinhole projection into a depth tile.
 *
 * bones: NB bone transforms, each a row-major 3x4 affine matrix [R | t] (3 float4 rows) that maps
 * a rest body-frame point (m) to the camera frame (m, OpenCV axes: x right, y down, z forward).
 */
#ifndef SWARMPOSE_SKIN_H
#define SWARMPOSE_SKIN_H

#include "include/util.h"

/* sum_k w_k (R_k v + t_k) over the 4 influences (unused slots carry weight 0), computed as
 * the blended matrix (three float4 rows) applied once. bones: NB x 3 rows [R | t]. Plain
 * multiply-adds: fma() is a slow library call on some CPU back ends (PoCL), where it cost
 * 4x the whole skinning step. */
inline float3 skin_lbs(__local const float4 *bones, const float4 rest, const int4 idx, const float4 w)
{
    __local const float4 *a = bones + 3 * idx.x;
    __local const float4 *b = bones + 3 * idx.y;
    __local const float4 *c = bones + 3 * idx.z;
    __local const float4 *d = bones + 3 * idx.w;
    const float4 r0 = w.x * a[0] + w.y * b[0] + w.z * c[0] + w.w * d[0];
    const float4 r1 = w.x * a[1] + w.y * b[1] + w.z * c[1] + w.w * d[1];
    const float4 r2 = w.x * a[2] + w.y * b[2] + w.z * c[2] + w.w * d[2];
    const float4 v = (float4)(rest.xyz, 1.0f);
    return (float3)(dot4(r0, v), dot4(r1, v), dot4(r2, v));
}

/* Camera point (m) -> (x_t, y_t, 1/z, 0): tile coordinates in tile pixels (pixel i has its
 * centre at i + 0.5) and inverse depth (1/m). proj = (ax, bx, ay, by): x_t = ax x/z + bx.
 * Points nearer than ZNEAR (or NaN) get 1/z = -1, which rejects every triangle using them. */
inline float4 project_tile(const float3 q, const float4 proj)
{
    if (!(q.z > ZNEAR))
        return (float4)(0.0f, 0.0f, -1.0f, 0.0f);
    const float iz = 1.0f / q.z;
    return (float4)(proj.x * (q.x * iz) + proj.y, proj.z * (q.y * iz) + proj.w, iz, 0.0f);
}

#endif
