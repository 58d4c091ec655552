/* Small helpers written out instead of OpenCL builtins.
 *
 * PoCL's CPU back end (3.0, as shipped with pyopencl) calls builtins such as min, max,
 * floor, ceil, clamp, dot, fabs, fmin, select and vload as out-of-line functions, which made
 * them a large part of the scorer's time; these plain expressions inline everywhere.
 */
#ifndef SWARMPOSE_UTIL_H
#define SWARMPOSE_UTIL_H

#define IMIN(a, b) ((a) < (b) ? (a) : (b))  /* scalars or vectors alike */
#define IMAX(a, b) ((a) > (b) ? (a) : (b))

/* floor / ceil of a float already clamped to a small range (|x| < 2^31), as int */
inline int ifloor(const float x)
{
    const int t = (int)x;
    return t - (x < (float)t);
}

inline int iceil(const float x)
{
    const int t = (int)x;
    return t + (x > (float)t);
}

/* clamp to [lo, hi]; NaN gives lo */
inline float clampf(const float x, const float lo, const float hi)
{
    const float y = x > lo ? x : lo;
    return y < hi ? y : hi;
}

/* ifloor / iceil / clampf of 8 lanes (the comparisons give -1 where true) */
inline int8 ifloor8(const float8 x)
{
    const int8 t = convert_int8(x);
    return t + (x < convert_float8(t));
}

inline int8 iceil8(const float8 x)
{
    const int8 t = convert_int8(x);
    return t - (x > convert_float8(t));
}

inline float8 clampf8(const float8 x, const float lo, const float hi)
{
    const float8 y = x > lo ? x : (float8)(lo);
    return y < hi ? y : (float8)(hi);
}

inline float dot4(const float4 a, const float4 b)
{
    return (a.x * b.x + a.y * b.y) + (a.z * b.z + a.w * b.w);
}

#endif
