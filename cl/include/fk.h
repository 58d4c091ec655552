/* Forward kinematics of one particle on the device: pose vector -> NB bone transforms.
 *
 * The same maths as swarmpose.body.kinematics (the numpy oracle), with quaternions along the
 * chain. Quaternions are float4 (x, y, z, w): vector part in .xyz, scalar in .w.
 *
 * Tables (constant per body, built by swarmpose.gpu.fk_tables):
 *   steps: NJ x 3 float4, joint j's rotations in multiplication order (E_j = R(s0) R(s1) R(s2)):
 *          unit axis in .xyz (body frame), index of its angle in the pose vector in .w (< 0: no step);
 *   links: NB int2 (parent bone, -1 for the root; tracking joint rotating the bone, -1: rigid);
 *   bone_data: NB x 4 float4: [0] = (rest head, m; share f of the joint's rotation),
 *          [1..3] = rows of the rest frame's transpose R_b^T (.xyz).
 * Bone b: canonical frame W_b = W_parent E_j^f (W_root = the pose's unit quaternion), delta
 * from rest D_b = W_b R_b^T, posed head x_b = D_parent p_b + t_parent (the parent's transform
 * applied to the rest head; x_root = the pose's translation), t_b = x_b - D_b p_b.
 * Output: bones[3 b + r] = row r of [D_b | t_b], as skin_lbs reads them.
 */
#ifndef SWARMPOSE_FK_H
#define SWARMPOSE_FK_H

#include "include/util.h"

#define POSE_DIM 36

/* dot and cross written out (PoCL calls the builtins out of line; see util.h) */
inline float dot3(const float3 a, const float3 b)
{
    return a.x * b.x + a.y * b.y + a.z * b.z;
}

inline float3 cross3(const float3 a, const float3 b)
{
    return (float3)(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x);
}

inline float4 quat_mul(const float4 a, const float4 b)
{
    return (float4)(a.w * b.xyz + b.w * a.xyz + cross3(a.xyz, b.xyz), a.w * b.w - dot3(a.xyz, b.xyz));
}

/* Rotation by angle (rad) about a unit axis. */
inline float4 quat_axis_angle(const float3 axis, const float angle)
{
    const float h = 0.5f * angle;
    return (float4)(axis * sin(h), cos(h));
}

/* q^f: the same axis, f times the angle (of the shorter way round, as the oracle's power). */
inline float4 quat_power(float4 q, const float f)
{
    if (q.w < 0.0f)
        q = -q;
    const float s = sqrt(dot3(q.xyz, q.xyz));
    if (s < 1e-12f)
        return (float4)(0.0f, 0.0f, 0.0f, 1.0f);
    const float angle = atan2(s, q.w) * f; /* half the new angle */
    return (float4)(q.xyz * (sin(angle) / s), cos(angle));
}

/* Rows of the rotation of a unit quaternion, times the columns of m (rows m0..m2): rows of R m. */
inline void quat_matrix_times(const float4 q, const float4 m0, const float4 m1, const float4 m2,
                              __local float4 *out)
{
    const float x = q.x, y = q.y, z = q.z, w = q.w;
    const float4 r0 = (float4)(1.0f - 2.0f * (y * y + z * z), 2.0f * (x * y - w * z), 2.0f * (x * z + w * y), 0.0f);
    const float4 r1 = (float4)(2.0f * (x * y + w * z), 1.0f - 2.0f * (x * x + z * z), 2.0f * (y * z - w * x), 0.0f);
    const float4 r2 = (float4)(2.0f * (x * z - w * y), 2.0f * (y * z + w * x), 1.0f - 2.0f * (x * x + y * y), 0.0f);
    out[0] = r0.x * m0 + r0.y * m1 + r0.z * m2;
    out[1] = r1.x * m0 + r1.y * m1 + r1.z * m2;
    out[2] = r2.x * m0 + r2.y * m1 + r2.z * m2;
}

/* Row-major [R | t] (3 float4 rows) applied to a point. */
inline float3 affine_apply(__local const float4 *rows, const float3 p)
{
    const float4 v = (float4)(p, 1.0f);
    return (float3)(dot4(rows[0], v), dot4(rows[1], v), dot4(rows[2], v));
}

/* All NB bone transforms of one pose (POSE_DIM floats) into bones (NB x 3 rows); joint_q (NJ)
 * and frame_q (NB) are scratch. */
inline void forward_kinematics(__global const float *pose, __global const float4 *steps,
                               __global const int2 *links, __global const float4 *bone_data,
                               __local float4 *joint_q, __local float4 *frame_q, __local float4 *bones)
{
    for (int j = 0; j < NJ; ++j) {
        float4 q = (float4)(0.0f, 0.0f, 0.0f, 1.0f);
        for (int k = 0; k < 3; ++k) {
            const float4 s = steps[3 * j + k];
            if (s.w >= 0.0f)
                q = quat_mul(q, quat_axis_angle(s.xyz, pose[(int)s.w]));
        }
        joint_q[j] = q;
    }
    float4 root = (float4)(pose[4], pose[5], pose[6], pose[3]);  /* pose: x, y, z, qw, qx, qy, qz, angles */
    root *= 1.0f / sqrt(dot4(root, root));
    for (int b = 0; b < NB; ++b) {
        const int2 link = links[b];
        const float4 head = bone_data[4 * b];
        float4 frame;
        if (link.x < 0)
            frame = root;
        else if (link.y < 0)
            frame = frame_q[link.x];
        else
            frame = quat_mul(frame_q[link.x], head.w == 1.0f ? joint_q[link.y] : quat_power(joint_q[link.y], head.w));
        frame_q[b] = frame;
        __local float4 *rows = bones + 3 * b;
        quat_matrix_times(frame, bone_data[4 * b + 1], bone_data[4 * b + 2], bone_data[4 * b + 3], rows);
        const float3 x = link.x < 0 ? (float3)(pose[0], pose[1], pose[2]) : affine_apply(bones + 3 * link.x, head.xyz);
        const float3 t = x - (float3)(dot3(rows[0].xyz, head.xyz), dot3(rows[1].xyz, head.xyz),
                                      dot3(rows[2].xyz, head.xyz));
        rows[0].w = t.x;
        rows[1].w = t.y;
        rows[2].w = t.z;
    }
}

#endif
