// Generalised winding numbers (trace.cl's query_winding_number and the
// "winding" sign of query_signed_distance_winding): w(p) = the sum of the
// signed solid angles of the triangles seen from p, over 4 pi -- 1 inside a
// closed, outward-wound mesh, 0 outside, and a smooth measure of "inside" for
// open meshes and soups (Jacobson et al. 2013).
//
// Exact solid angle of one triangle: van Oosterom and Strackee (1983),
// tan(omega / 2) = det(a, b, c) / (|a||b||c| + (a.b)|c| + (b.c)|a| + (c.a)|b|),
// a, b, c the corners seen from p, in double precision where the device has
// it.  A point in the triangle's plane (det exactly 0) gets 0 from it: inside
// the triangle that is the mean of the +-2 pi on either side, so a point on a
// closed surface's face has w = 1/2.
//
// Through the BVH (Barill et al. 2018, "Fast winding numbers for soups and
// clouds"): each child carries the first three terms of the Taylor series of
// its triangles' solid angles about their centre (a WindingNode, layouts.h:
// the dipole, and the symmetric parts of the first and second moments of the
// normals), and the walk takes a child whose every corner lies within its
// radius r of the centre, while p lies farther than beta r from it, from that
// series instead of opening it; the rest it opens, down to exact leaves.  The
// series is evaluated in float32 (its terms are each within some 20 ulps of
// the child's A / R^2, A its area, R the distance: far below the series' own
// error) and summed in double precision.
//
// Values (winding_number): beta = WINDING_BETA = 6.  The series' error falls
// as (r / distance)^3 times the child's own solid angle, and the errors of
// many children partly cancel: 6 kept the largest error of 200 points in and
// around each of seven scans (4k to 75k triangles, device-built trees) at
// 2.1e-5 and of the tests' meshes at 1e-5, against the exact sum
// (clrt.query.results.WINDING_NUMBER_ERROR is 1e-4; tests/test_inside.py);
// with the float32 series, 2.8e-5 over eight scans (sphere volumes, whose
// CPU walk is the binary one; docs/benchmark-log.md, 2026-12-02).
// On one of those scans (cow, a host SAH tree) 2, Barill's choice, gave
// 5.6e-3, and 4 gave 1.8e-4 -- 4.2e-3 without the series' last term.
// Without a BVH every triangle is summed exactly.
//
// On GPUs (-DPOINT_CELL_REGIONS) "farther than beta r" is asked of the
// point's whole cell (point_order.cl's point_region): the points of a cell,
// neighbours in the launch, then open the same children and walk in
// lockstep, each summing its own series and leaves.  A child far from the
// cell is far from the point, so the error can only shrink; on the H200 the
// walk of a million random points took half the time (docs/benchmarks.md).
// The stricter test leaves room for a smaller beta there, 4.5: on the tests'
// meshes (tests/test_inside.py: this program on the CPU) the largest error
// was 5.4e-5 (beta 6: 2.0e-5); float32 leaves, tried beside it, missed
// WINDING_NUMBER_ERROR by half (1.5e-4 at a point just off a large face).
// A two-level scene's walk (winding_placed.cl) asks it of the point alone,
// region or not, so it keeps beta 6 there.
//
// CPU devices that walk the wide BVH (-DBVH_WIDE, accel_wide.cl) walk it here
// too: one float8 series for the eight children of a wide node
// (WideWindingNode), and a leaf's packets of four triangles in double4.  Its
// lanes are the binary children a level or two below those the binary walk
// would take, so the same beta is more exact there: 5 keeps the largest error
// of eight scans (4k to 75k triangles; 200 points each as the tests make
// them) at 2.7e-5 (6: 1.4e-5) and takes 30 % off bunny00's time.
//
// Inside or not (winding_inside: contains, the "winding" sign) needs only the
// side of 1/2, so a first walk takes beta = WINDING_SIGN_BETA (3; 2.5 on the
// wide BVH: on bunny00 each the fastest, the second walk included) and adds
// up a proven bound of its own error (remainder_bound); only where that
// leaves the side in doubt does the second, winding_number's walk decide --
// see winding_inside for why the two agree.
#ifndef CLRT_WINDING_CL
#define CLRT_WINDING_CL

#include "geometry.cl"
#include "point.cl"
#include "point_order.cl"
#include "lanes.cl"

#ifdef BVH_WIDE
#define WINDING_BETA 5.0f
#define WINDING_SIGN_BETA 2.5f
#elif defined(POINT_CELL_REGIONS) && !defined(ACCEL_INSTANCES)
#define WINDING_BETA 4.5f
#define WINDING_SIGN_BETA 3.0f
#else
#define WINDING_BETA 6.0f
#define WINDING_SIGN_BETA 3.0f
#endif
#define INV_4PI 0.07957747154594767

// How far from 1/2 winding_inside's first walk must put a point, beyond its
// own error bound, to decide: ten times WINDING_NUMBER_ERROR, the documented
// error of winding_number's values (see winding_inside).
#define WINDING_SIGN_MARGIN 1e-3

// The far fields the walk reads: a WindingNode per child of a binary row, or
// on CPU devices that walk the wide BVH a WideWindingNode per wide node.
// A two-level scene's rows hold PlacedWindingNodes (winding_placed.cl).
#if defined(ACCEL_INSTANCES)
typedef PlacedWindingNode WindingFarField;
#elif defined(BVH_WIDE)
typedef WideWindingNode WindingFarField;
#else
typedef WindingNode WindingFarField;
#endif
// What trace.cl's winding_nodes makes, a node a child of a binary row.
#ifdef ACCEL_INSTANCES
typedef PlacedWindingNode RowWindingNode;
#else
typedef WindingNode RowWindingNode;
#endif

// The signed solid angle of triangle (a, b, c) seen from p: positive where p
// lies behind its face ((b - a) x (c - a) points away from p).
inline point_real solid_angle(point_real3 p, point_real3 a, point_real3 b, point_real3 c)
{
    a -= p;
    b -= p;
    c -= p;
    const point_real la = sqrt(dot(a, a)), lb = sqrt(dot(b, b)), lc = sqrt(dot(c, c));
    const point_real det = dot(a, cross(b, c));
    if (det == 0)
        return 0;
    const point_real den = la * lb * lc + dot(a, b) * lc + dot(b, c) * la + dot(c, a) * lb;
    return 2 * atan2(det, den);
}

// The solid angles of slots first .. first + count - 1 seen from p, summed.
inline point_real leaf_solid_angle(const Geometry* g, point_real3 p, int first, int count)
{
    point_real sum = 0;
    for (int s = first; s < first + count; ++s) {
        __global const TriangleVerts* t = SPLIT_AT(g, tris, s);
        sum += solid_angle(p, TO_POINT_REAL3(t->v0.xyz), TO_POINT_REAL3(t->v1.xyz), TO_POINT_REAL3(t->v2.xyz));
    }
    return sum;
}

// The series of a far field at p, times 4 pi, for a scalar (float) or lanes
// (float8) of children: with (x, y, z) = r = centre - p, R = |r|, N the
// dipole, S1 and S2 the symmetric first and second moments and
// c_k = sum_i S2[i][i][k],
//   N.r / R^3
// + (tr S1 - 3 r.S1 r / R^2) / R^3
// + (15 S2[r, r, r] / R^4 - 9 r.c / R^2) / (2 R^3):
// the three terms of integral n . (x - p) / |x - p|^3 dA with (x - p) / |x - p|^3
// expanded about the centre (its first and second derivatives, symmetric
// tensors, contracted with the moments).
#define DEFINE_FAR_FIELD(NAME, T) \
inline T NAME(T x, T y, T z, T r2, T nx, T ny, T nz, __global const T* s1, __global const T* s2) \
{ \
    const T inv_r = rsqrt(r2);            /* not 1 / r2: volumes.cl's bound_length says why */ \
    const T inv_r2 = inv_r * inv_r; \
    const T xx = x * x, yy = y * y, zz = z * z; \
    const T order0 = nx * x + ny * y + nz * z; \
    const T s1rr = s1[0] * xx + s1[3] * yy + s1[5] * zz + 2.0f * (s1[1] * x * y + s1[2] * x * z + s1[4] * y * z); \
    const T order1 = s1[0] + s1[3] + s1[5] - 3.0f * s1rr * inv_r2; \
    const T s2rrr = x * (s2[0] * xx + 3.0f * (s2[1] * x * y + s2[2] * x * z + s2[3] * yy + s2[5] * zz) \
                         + 6.0f * s2[4] * y * z) \
                  + y * (s2[6] * yy + 3.0f * (s2[7] * y * z + s2[8] * zz)) + s2[9] * z * zz; \
    const T cr = x * (s2[0] + s2[3] + s2[5]) + y * (s2[1] + s2[6] + s2[8]) + z * (s2[2] + s2[7] + s2[9]); \
    const T order2 = 0.5f * (15.0f * s2rrr * inv_r2 - 9.0f * cr) * inv_r2; \
    return (order0 + order1 + order2) * inv_r2 * inv_r; \
}
DEFINE_FAR_FIELD(far_field, float)
#ifdef BVH_WIDE
DEFINE_FAR_FIELD(far_field_lanes, float8)
#endif

// A proven bound of the error of a child's series at p, times 4 pi (area A,
// radius r, r2 = R^2, q = r / R < 1).  (x - p) / |x - p|^3 . n is the
// derivative along n of -1 / |x - p|; the k-th derivative of 1 / |y| along one
// direction is k! P_k(cos) / |y|^(k + 1), |P_k| <= 1 (Legendre's generating
// function), and a symmetric multilinear form is no larger on mixed directions
// than on one (Banach 1938); so the series' term of order k is at most
// (k + 1) (r / R)^k / R^2 a unit of area, and the remainder after the terms of
// order 0, 1, 2, summed over k >= 3, is at most
//   A / R^2 * sum_{k >= 3} (k + 1) q^k = A / R^2 * q^3 (4 - 3 q) / (1 - q)^2.
// Added: 2^-12 A / R^2 for the float32 evaluation (|N| <= A, |S1| <= A r and
// |S2| <= A r^2 entry by entry, so for q <= 0.4 the products it sums are at
// most some 30 A / R^2 in all, each rounded at most some 30 times, and 1 /
// R^2 taken through rsqrt within some 5 ulps: within 7e-5 A / R^2), and
// 1/1000 of the whole for the rounding of this bound and of A.
#define DEFINE_REMAINDER_BOUND(NAME, T) \
inline T NAME(T area, T radius, T r2) \
{ \
    const T inv_r = rsqrt(r2); \
    const T q = radius * inv_r; \
    return 1.001f * area * inv_r * inv_r * (q * q * q * (4.0f - 3.0f * q) / ((1.0f - q) * (1.0f - q)) + 0x1p-12f); \
}
DEFINE_REMAINDER_BOUND(remainder_bound, float)
#ifdef BVH_WIDE
DEFINE_REMAINDER_BOUND(remainder_bound_lanes, float8)

// The sum of the eight lanes.
inline float lanes_sum(float8 v)
{
    const float4 a = v.lo + v.hi;
    const float2 b = a.lo + a.hi;
    return b.x + b.y;
}

#ifdef cl_khr_fp64
typedef double4 point_real4;
#define TO_POINT_REAL4 convert_double4
#else
typedef float4 point_real4;
#define TO_POINT_REAL4(x) (x)
#endif

// The solid angles of the triangles of a leaf's packets first .. first +
// count - 1 seen from p, summed: solid_angle's steps, four triangles a time
// (an empty lane's corners are zeros, their det exactly 0).
inline point_real leaf_packets_solid_angle(const Geometry* g, point_real3 p, int first, int count)
{
    point_real4 sum = 0;
    for (int k = first; k < first + count; ++k) {
        __global const TrianglePacket* t = g->packets + k;
        const point_real4 ax = TO_POINT_REAL4(t->v0[0]) - p.x, ay = TO_POINT_REAL4(t->v0[1]) - p.y;
        const point_real4 az = TO_POINT_REAL4(t->v0[2]) - p.z;
        const point_real4 bx = TO_POINT_REAL4(t->v1[0]) - p.x, by = TO_POINT_REAL4(t->v1[1]) - p.y;
        const point_real4 bz = TO_POINT_REAL4(t->v1[2]) - p.z;
        const point_real4 cx = TO_POINT_REAL4(t->v2[0]) - p.x, cy = TO_POINT_REAL4(t->v2[1]) - p.y;
        const point_real4 cz = TO_POINT_REAL4(t->v2[2]) - p.z;
        const point_real4 la = sqrt(ax * ax + ay * ay + az * az), lb = sqrt(bx * bx + by * by + bz * bz);
        const point_real4 lc = sqrt(cx * cx + cy * cy + cz * cz);
        const point_real4 det = ax * (by * cz - bz * cy) + ay * (bz * cx - bx * cz) + az * (bx * cy - by * cx);
        const point_real4 den = la * lb * lc + (ax * bx + ay * by + az * bz) * lc + (bx * cx + by * cy + bz * cz) * la
                              + (cx * ax + cy * ay + cz * az) * lb;
        sum += select(2 * atan2(det, den), (point_real4)(0), det == 0);
    }
    return sum.x + sum.y + sum.z + sum.w;
}
#endif

// Index of the symmetric pair (i, j) among first[6], and the index triples
// of second[10], as layouts.h orders them.
__constant uchar SYM2_AT[3][3] = {{0, 1, 2}, {1, 3, 4}, {2, 4, 5}};
__constant uchar SYM3_OF[10][3] = {{0, 0, 0}, {0, 0, 1}, {0, 0, 2}, {0, 1, 1}, {0, 1, 2},
                                   {0, 2, 2}, {1, 1, 1}, {1, 1, 2}, {1, 2, 2}, {2, 2, 2}};

// The float32 radius of a child from its double one: rounded up.
inline float radius_up(point_real r)
{
    const float f = (float)r;
    return (point_real)f >= r ? f : nextafter(f, INFINITY);
}

// The area of the triangles in slots first .. first + count - 1 (*area) and
// their area-weighted centroid, rounded to float32: the centre a leaf's
// far field is taken about (leaf_winding_node, leaf_placed_winding_node).
inline float3 leaf_centre(const Geometry* g, int first, int count, point_real* area_out)
{
    point_real area = 0;
    point_real3 weighted = (point_real3)(0), mean = (point_real3)(0);
    for (int s = first; s < first + count; ++s) {
        __global const TriangleVerts* t = SPLIT_AT(g, tris, s);
        const point_real3 a = TO_POINT_REAL3(t->v0.xyz), b = TO_POINT_REAL3(t->v1.xyz);
        const point_real3 c = TO_POINT_REAL3(t->v2.xyz);
        const point_real3 vector_area = cross(b - a, c - a) / 2;
        const point_real at = sqrt(dot(vector_area, vector_area));
        area += at;
        weighted += at * (a + b + c) / 3;
        mean += (a + b + c) / 3;
    }
    *area_out = area;
    // Triangles of no area: any centre serves (their series is zero), the mean of their centroids.
    return convert_float3(area > 0 ? weighted / area : mean / count);
}

#include "winding_placed.cl"

// The sum of the solid angles of the mesh seen from p (device frame), with
// each child farther than beta times its radius taken from its series;
// `winding`: the far fields (unused without a BVH).  With `bounded`, *bound
// is set to a proven bound of the sum's error (remainder_bound).
#if defined(ACCEL_INSTANCES)
// (A two-level scene's walk: winding_placed.cl.)
#elif defined(ACCEL_BVH) && defined(BVH_WIDE)
inline point_real winding_sum(const Geometry* g, __global const WindingFarField* winding, float3 p,
                              const PointRegion* region, float beta, const bool bounded, float* bound)
{
    const point_real3 pr = TO_POINT_REAL3(p);
    point_real sum = 0;
    float err = 0.0f;
    // Each node pushes its near inner children and takes the last: at most
    // WIDE - 1 more a level.
    int stack[WIDE_STACK_SIZE];
    int sp = 0;
    int node = 0;
    for (;;) {
        __global const BvhWideNode* n = g->wide_nodes + node;
        __global const WideWindingNode* w = winding + node;
        const float8 x = w->cx - p.x, y = w->cy - p.y, z = w->cz - p.z;
        const float8 r2 = x * x + y * y + z * z;
        const float8 reach = beta * w->radius;
        const int8 present = n->count >= 0;
        const int8 far = present & (r2 > reach * reach);
        if (any(far)) {
            sum += lanes_sum(select((float8)(0.0f),
                                    far_field_lanes(x, y, z, r2, w->nx, w->ny, w->nz, w->first, w->second), far));
            if (bounded)
                err += lanes_sum(select((float8)(0.0f), remainder_bound_lanes(w->area, w->radius, r2), far));
        }
        __global const int* child = (__global const int*)&n->child;
        __global const int* count = (__global const int*)&n->count;
        for (uint near = lane_bits(present & ~far); near; near &= near - 1u) {
            const int k = 31 - clz(near & (0u - near));
            if (count[k] > 0)
                sum += leaf_packets_solid_angle(g, pr, child[k], count[k]);
            else
                stack[sp++] = child[k];
        }
        if (sp == 0)
            break;
        node = stack[--sp];
    }
    if (bounded)
        *bound = err;
    return sum;
}
#else
inline point_real winding_sum(const Geometry* g, __global const WindingFarField* winding, float3 p,
                              const PointRegion* region, float beta, const bool bounded, float* bound)
{
    const point_real3 pr = TO_POINT_REAL3(p);
    point_real sum = 0;
    float err = 0.0f;
#ifdef ACCEL_BVH
    // Every near inner child is opened; the right one waits on the stack while
    // the left is walked, so it holds at most one row a level.
    int stack[BVH_STACK_SIZE];
    int sp = 0;
    int row = 0;
    for (;;) {
        const BvhPairNode n = *SPLIT_AT(g, nodes, row);
        int next = -1;
        for (int side = 0; side < 2; ++side) {
            const int2 child = side == 0 ? PAIR_LEFT(n) : PAIR_RIGHT(n);
            if (child.y < 0)
                continue;
            __global const WindingNode* node = winding + 2 * row + side;
            const float3 r = node->centre.xyz - p;
            const float r2 = dot(r, r);
            const float reach = beta * node->centre.w;
            if (region_distance2(region, node->centre.xyz) > reach * reach) {
                sum += far_field(r.x, r.y, r.z, r2, node->normal.x, node->normal.y, node->normal.z, node->first,
                                 node->second);
                if (bounded)
                    err += remainder_bound(node->normal.w, node->centre.w, r2);
            } else if (child.y > 0) {
                sum += leaf_solid_angle(g, pr, child.x, child.y);
            } else if (next < 0) {
                next = child.x;
            } else {
                stack[sp++] = child.x;
            }
        }
        if (next < 0) {
            if (sp == 0)
                break;
            next = stack[--sp];
        }
        row = next;
    }
#else
    sum = leaf_solid_angle(g, pr, 0, (int)g->num_tris);
#endif
    if (bounded)
        *bound = err;
    return sum;
}
#endif

// The winding number of the mesh at p (device frame); `winding`: the far
// fields (unused without a BVH).
inline point_real winding_number(const Geometry* g, __global const WindingFarField* winding, float3 p,
                                 const PointRegion* region)
{
    float unused;
    return winding_sum(g, winding, p, region, WINDING_BETA, false, &unused) * INV_4PI;
}

// Is p inside -- (float)winding_number(p) >= 1/2?  A first walk with
// WINDING_SIGN_BETA gives w1 and a proven bound e1 of |w1 - w| (w the exact
// sum; the solid angles of the leaves' triangles are taken as exact: they are
// double precision).  Where |w1 - 1/2| > e1 + WINDING_SIGN_MARGIN, the exact
// w lies more than WINDING_SIGN_MARGIN from 1/2, on w1's side, and so does
// winding_number's value as long as it keeps within WINDING_SIGN_MARGIN of w
// -- ten times its documented error (clrt.query.results.WINDING_NUMBER_ERROR).
// Elsewhere winding_number decides, so the two agree there by construction.
// (Without double precision the leaves are float32 too: no first walk.)
inline bool winding_inside(const Geometry* g, __global const WindingFarField* winding, float3 p,
                           const PointRegion* region)
{
#if defined(ACCEL_BVH) && defined(cl_khr_fp64)
    float bound;
    const point_real w1 = winding_sum(g, winding, p, region, WINDING_SIGN_BETA, true, &bound) * INV_4PI;
    if (fabs(w1 - (point_real)0.5) > bound * INV_4PI + WINDING_SIGN_MARGIN)
        return w1 > 0.5;
#endif
    return (float)winding_number(g, winding, p, region) >= 0.5f;
}

// ---- The WindingNodes of a tree, made level by level from the deepest up
// (trace.cl's winding_nodes): a leaf child's from its triangles, an inner
// child's from its row's two, so that each level reads only finished ones.
// Sums in double precision where the device has it; the centre is rounded to
// float32 first and every moment taken about the rounded one.

// A WindingNode of its centre and radius, its dipole and area, and the
// symmetric parts of its first (6) and second (10) moments, rounded to float32.
inline WindingNode winding_node_of(float3 centre, float radius, point_real3 dipole, point_real area,
                                   const point_real* m, const point_real* sec)
{
    WindingNode node;
    node.centre = (float4)(centre, radius);
    node.normal = (float4)(convert_float3(dipole), (float)area);
    for (int k = 0; k < 6; ++k)
        node.first[k] = (float)m[k];
    for (int k = 0; k < 10; ++k)
        node.second[k] = (float)sec[k];
    return node;
}

// The WindingNode of the triangles in slots first .. first + count - 1.  With
// v a triangle's vector area (area times unit normal), m its centroid and
// Q[j][k] = integral of d_j d_k over it / area = (sum of its corners' d_j d_k
// + (sum d)_j (sum d)_k) / 12: first = sym(sum v (x) m), second = sym(sum v (x) Q).
inline WindingNode leaf_winding_node(const Geometry* g, int first, int count)
{
    point_real area;
    const float3 centre = leaf_centre(g, first, count, &area);
    const point_real3 cr = TO_POINT_REAL3(centre);
    point_real3 dipole = (point_real3)(0);
    point_real m[6] = {0, 0, 0, 0, 0, 0};
    point_real sec[10] = {0, 0, 0, 0, 0, 0, 0, 0, 0, 0};
    point_real radius2 = 0;
    for (int s = first; s < first + count; ++s) {
        __global const TriangleVerts* t = SPLIT_AT(g, tris, s);
        const point_real3 d0 = TO_POINT_REAL3(t->v0.xyz) - cr, d1 = TO_POINT_REAL3(t->v1.xyz) - cr;
        const point_real3 d2 = TO_POINT_REAL3(t->v2.xyz) - cr;
        radius2 = fmax(radius2, fmax(dot(d0, d0), fmax(dot(d1, d1), dot(d2, d2))));
        const point_real3 va = cross(d1 - d0, d2 - d0) / 2;
        const point_real3 sum = d0 + d1 + d2;
        dipole += va;
        const point_real v[3] = {va.x, va.y, va.z};
        const point_real mid[3] = {sum.x / 3, sum.y / 3, sum.z / 3};
        const point_real x0[3] = {d0.x, d0.y, d0.z}, x1[3] = {d1.x, d1.y, d1.z}, x2[3] = {d2.x, d2.y, d2.z};
        const point_real sx[3] = {sum.x, sum.y, sum.z};
        point_real q[3][3];
        for (int j = 0; j < 3; ++j)
            for (int k = 0; k < 3; ++k)
                q[j][k] = (x0[j] * x0[k] + x1[j] * x1[k] + x2[j] * x2[k] + sx[j] * sx[k]) / 12;
        for (int i = 0; i < 3; ++i)
            for (int j = i; j < 3; ++j)
                m[SYM2_AT[i][j]] += (v[i] * mid[j] + v[j] * mid[i]) / 2;
        for (int t3 = 0; t3 < 10; ++t3) {
            const int i = SYM3_OF[t3][0], j = SYM3_OF[t3][1], k = SYM3_OF[t3][2];
            sec[t3] += (v[i] * q[j][k] + v[j] * q[i][k] + v[k] * q[i][j]) / 3;
        }
    }
    return winding_node_of(centre, radius_up(sqrt(radius2)), dipole, area, m, sec);
}

// The WindingNode of two children joined (an inner child: its row's two
// WindingNodes, `a` and `b`): moments moved to the joint centre and summed,
// the radius the farthest child's reach.  With e = child centre - joint
// centre (d = d' + e) the full moments move as M + N (x) e and
// T + M (x) e + (M (x) e)^(jk swapped) + N (x) e (x) e; their symmetric parts
// therefore as S1 + sym(N (x) e) and S2 + 2 sym(S1 (x) e) + sym(N (x) e (x) e).
inline WindingNode joined_winding_node(__global const WindingNode* a, __global const WindingNode* b)
{
    const point_real area_a = a->normal.w, area_b = b->normal.w;
    const point_real3 ca = TO_POINT_REAL3(a->centre.xyz), cb = TO_POINT_REAL3(b->centre.xyz);
    const point_real area = area_a + area_b;
    const float3 centre = convert_float3(area > 0 ? (area_a * ca + area_b * cb) / area : (ca + cb) / 2);
    const point_real3 cr = TO_POINT_REAL3(centre);
    point_real radius = 0;
    point_real3 dipole = (point_real3)(0);
    point_real m[6] = {0, 0, 0, 0, 0, 0};
    point_real sec[10] = {0, 0, 0, 0, 0, 0, 0, 0, 0, 0};
    for (int c = 0; c < 2; ++c) {
        __global const WindingNode* child = c == 0 ? a : b;
        const point_real3 e3 = TO_POINT_REAL3(child->centre.xyz) - cr;
        radius = fmax(radius, sqrt(dot(e3, e3)) + child->centre.w);
        const point_real3 n3 = TO_POINT_REAL3(child->normal.xyz);
        dipole += n3;
        const point_real e[3] = {e3.x, e3.y, e3.z}, n[3] = {n3.x, n3.y, n3.z};
        point_real s1[3][3];
        for (int i = 0; i < 3; ++i)
            for (int j = 0; j < 3; ++j)
                s1[i][j] = child->first[SYM2_AT[i][j]];
        for (int i = 0; i < 3; ++i)
            for (int j = i; j < 3; ++j)
                m[SYM2_AT[i][j]] += s1[i][j] + (n[i] * e[j] + n[j] * e[i]) / 2;
        for (int t3 = 0; t3 < 10; ++t3) {
            const int i = SYM3_OF[t3][0], j = SYM3_OF[t3][1], k = SYM3_OF[t3][2];
            sec[t3] += child->second[t3] + 2 * (s1[i][j] * e[k] + s1[j][k] * e[i] + s1[i][k] * e[j]) / 3
                     + (n[i] * e[j] * e[k] + n[j] * e[i] * e[k] + n[k] * e[i] * e[j]) / 3;
        }
    }
    return winding_node_of(centre, radius_up(radius), dipole, area, m, sec);
}

// The RowWindingNode of a row's child (trace.cl's winding_nodes): a leaf's
// from its triangles -- in a two-level scene's top level, its instance's mesh
// mapped into the world --, an inner child's from its own row's two (made by
// an earlier launch), a missing child's zeros.
inline RowWindingNode child_winding_node(const Geometry* g, __global const RowWindingNode* winding, int2 child,
                                         const bool top_level)
{
#ifdef ACCEL_INSTANCES
    if (child.y > 0)
        return top_level ? instance_winding_node(g, winding, child.x) : leaf_placed_winding_node(g, child.x, child.y);
    if (child.y == 0)
        return joined_placed_winding_node(winding + 2 * child.x, winding + 2 * child.x + 1, true);
    return empty_placed_winding_node();
#else
    if (child.y > 0)
        return leaf_winding_node(g, child.x, child.y);
    if (child.y == 0)
        return joined_winding_node(winding + 2 * child.x, winding + 2 * child.x + 1);
    WindingNode none = {(float4)(0.0f), (float4)(0.0f), {0}, {0}};
    return none;
#endif
}

#endif
