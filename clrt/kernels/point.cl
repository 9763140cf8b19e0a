// Point queries (trace.cl's query_closest_point): the point of the mesh
// nearest to each query point, by brute force or by a walk over the binary
// BVH rows (BvhPairNode) that every BVH device has -- CPU devices' wide BVH
// included, whose binary rows stay uploaded beside it.
//
// The closest point on one triangle is Ericson's region test ("Real-Time
// Collision Detection", 5.1.5): the point's projections onto the edges decide
// whether a vertex, an edge or the face is nearest.  It runs in double
// precision where the device has it (as trace.cl's face_normal), else in
// float32, on the float32 corners of the device's frame; the distance is
// rounded to float32 once, at the end.
//
// The walk visits children nearest first and drops a child whose volume lies
// farther than the best distance so far plus a margin (POINT_MARGIN): the
// volumes' lower bounds (volumes.cl, point_bound) are float32, so the margin
// keeps every triangle that brute force could pick -- each walk then computes
// the same distances for the same triangles and gives brute force's answer
// bit for bit.  Ties go to the lower input triangle index, as hit.cl's.
//
// CPU devices that walk the wide BVH (-DBVH_WIDE, accel_wide.cl) walk it
// here too (walk_wide_points): the box distances of a node's eight children
// in one float8 computation, nearest first, and a leaf's packets of four
// triangles through a float32 lower bound of each one's distance
// (packet_distance_bounds), proven to lie below the double precision one
// that visit_point_triangle would compute: only a triangle that could still
// be the answer (or tie with it) is visited, so the answer is the binary
// walk's and brute force's, bit for bit.  Where such a device walks ray
// packets, the closest-point kernels walk sixteen points at once instead
// (point_group.cl), through the same bounds.  On NVIDIA GPUs the 32 points of
// a warp walk together (point_warp.cl).
//
// Below the walk, two of the sign rules of signed distances (the third,
// winding numbers, is winding.cl): parity of ray crossings, and the
// pseudo-normal at the feature -- face, edge or vertex -- that holds the
// closest point.
#ifndef CLRT_POINT_CL
#define CLRT_POINT_CL

#include "geometry.cl"
#include "volumes.cl"
#include "stack.cl"
#include "accel.cl"
#include "lanes.cl"

#ifdef cl_khr_fp64
typedef double point_real;
typedef double3 point_real3;
#define TO_POINT_REAL3 convert_double3
#else
typedef float point_real;
typedef float3 point_real3;
#define TO_POINT_REAL3(x) (x)
#endif

// Which part of a triangle holds its point nearest to p (closest_on_triangle):
// the face, corner FEATURE_VERTEX + k, or edge FEATURE_EDGE + k, from corner k
// to corner k + 1 (mod 3).  The signs by normal take the pseudo-normal there.
#define FEATURE_FACE 0
#define FEATURE_VERTEX 1
#define FEATURE_EDGE 4

// The best triangle so far: its input index, distance (inclusive bound while
// prim < 0), closest point (device frame) and barycentric weights of v1, v2,
// its slot and the feature (FEATURE_*) the point lies on; in a two-level
// scene its instance (0 in a one-level one).
typedef struct {
    int prim;
    point_real dist;
    point_real3 point;
    float u, v;
    int slot, feature;
    int instance;
} PointHit;

// Closest point to p on the segment a + t (b - a), t in [0, 1]; *t set.
inline point_real3 closest_on_segment(point_real3 p, point_real3 a, point_real3 b, point_real* t)
{
    const point_real3 ab = b - a;
    const point_real len2 = dot(ab, ab);
    point_real s = len2 > 0 ? dot(p - a, ab) / len2 : 0;
    s = s < 0 ? 0 : (s > 1 ? 1 : s);
    *t = s;
    return a + s * ab;
}

// Closest point to p on triangle (a, b, c), with the barycentric weights of
// b (*u) and c (*v) of that point and the feature it lies on (FEATURE_*).
inline point_real3 closest_on_triangle(point_real3 p, point_real3 a, point_real3 b, point_real3 c,
                                       point_real* u, point_real* v, int* feature)
{
    const point_real3 ab = b - a, ac = c - a, ap = p - a;
    const point_real d1 = dot(ab, ap), d2 = dot(ac, ap);
    if (d1 <= 0 && d2 <= 0) {                    // behind a on both edges from it: vertex a
        *u = 0; *v = 0;
        *feature = FEATURE_VERTEX;
        return a;
    }
    const point_real3 bp = p - b;
    const point_real d3 = dot(ab, bp), d4 = dot(ac, bp);
    if (d3 >= 0 && d4 <= d3) {                   // past b: vertex b
        *u = 1; *v = 0;
        *feature = FEATURE_VERTEX + 1;
        return b;
    }
    const point_real vc = d1 * d4 - d3 * d2;     // (scaled) weight of c: <= 0 outside edge ab
    if (vc <= 0 && d1 >= 0 && d3 <= 0) {
        const point_real t = d1 / (d1 - d3);
        *u = t; *v = 0;
        *feature = FEATURE_EDGE;
        return a + t * ab;
    }
    const point_real3 cp = p - c;
    const point_real d5 = dot(ab, cp), d6 = dot(ac, cp);
    if (d6 >= 0 && d5 <= d6) {                   // past c: vertex c
        *u = 0; *v = 1;
        *feature = FEATURE_VERTEX + 2;
        return c;
    }
    const point_real vb = d5 * d2 - d1 * d6;     // weight of b: <= 0 outside edge ac
    if (vb <= 0 && d2 >= 0 && d6 <= 0) {
        const point_real t = d2 / (d2 - d6);
        *u = 0; *v = t;
        *feature = FEATURE_EDGE + 2;
        return a + t * ac;
    }
    const point_real va = d3 * d6 - d5 * d4;     // weight of a: <= 0 outside edge bc
    if (va <= 0 && d4 - d3 >= 0 && d5 - d6 >= 0) {
        const point_real t = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        *u = 1 - t; *v = t;
        *feature = FEATURE_EDGE + 1;
        return b + t * (c - b);
    }
    const point_real sum = va + vb + vc;
    if (!(sum > 0)) {
        // A triangle of no area (or one rounding made so): the nearest of its
        // three edges, rather than a division by zero.
        point_real t0, t1, t2;
        const point_real3 q0 = closest_on_segment(p, a, b, &t0);
        const point_real3 q1 = closest_on_segment(p, a, c, &t1);
        const point_real3 q2 = closest_on_segment(p, b, c, &t2);
        const point_real e0 = dot(p - q0, p - q0), e1 = dot(p - q1, p - q1), e2 = dot(p - q2, p - q2);
        if (e0 <= e1 && e0 <= e2) {
            *u = t0; *v = 0;
            *feature = FEATURE_EDGE;
            return q0;
        }
        if (e1 <= e2) {
            *u = 0; *v = t1;
            *feature = FEATURE_EDGE + 2;
            return q1;
        }
        *u = 1 - t2; *v = t2;
        *feature = FEATURE_EDGE + 1;
        return q2;
    }
    *feature = FEATURE_FACE;
    *u = vb / sum;
    *v = vc / sum;
    return a + *u * ab + *v * ac;
}

// Take the triangle in `slot` (of `instance`, as it places it in the world:
// instances.cl's placed_corners) into *best if it is nearer, or as near with
// a lower instance, then input index (hit.cl's tie rule).
inline void visit_point_triangle(const Geometry* g, point_real3 p, int instance, int slot, PointHit* best)
{
    float3 a, b, c;
    placed_corners(g, instance, slot, &a, &b, &c);
    point_real u, v;
    int feature;
    const point_real3 q = closest_on_triangle(p, TO_POINT_REAL3(a), TO_POINT_REAL3(b), TO_POINT_REAL3(c),
                                              &u, &v, &feature);
    const point_real dist = sqrt(dot(p - q, p - q));
    if (dist > best->dist)
        return;
    const int prim = *SPLIT_AT(g, prim_ids, slot);
    if (dist == best->dist && best->prim >= 0
        && (instance > best->instance || (instance == best->instance && prim > best->prim)))
        return;
    best->instance = instance;
    best->prim = prim;
    best->dist = dist;
    best->point = q;
    best->u = (float)u;
    best->v = (float)v;
    best->slot = slot;
    best->feature = feature;
}

// How much farther than the best distance a volume may seem and still be
// entered: 2^-16 of the largest coordinate of the point and the scene's box
// (device frame), some 256 float32 ulps of the values the lower bounds round.
#define POINT_MARGIN(p, lo, hi) \
    (0x1p-16f * fmax(fmax(fmax(fabs((p).x), fabs((p).y)), fabs((p).z)), \
                     fmax(fmax(fmax(fabs((lo).x), fabs((lo).y)), fabs((lo).z)), \
                          fmax(fmax(fabs((hi).x), fabs((hi).y)), fabs((hi).z)))))

#if defined(ACCEL_BVH) && defined(BVH_WIDE)
// How much nearer than the best distance so far a triangle's lower bound must
// lie for walk_wide_points to visit it: 2^-24 of POINT_MARGIN, 2^-40 of the
// largest coordinate -- above the rounding of visit_point_triangle's double
// precision distance (its closest point lies on the triangle, or in its plane,
// to within some ulps of the coordinates), so that a triangle it skips
// computes farther than the best, never as near.  Without double precision
// that distance is float32: the whole margin.
#ifdef cl_khr_fp64
#define POINT_TIE_SLACK(margin) (0x1p-24f * (margin))
#else
#define POINT_TIE_SLACK(margin) (margin)
#endif

// Bounds of the distances from points to triangles, in float32: below the
// double precision distance that visit_point_triangle would compute, and
// (upper) above it.  For any unit vector n, no point x of a triangle (a, b,
// c) lies nearer to p than the least of n.(p - x) over its corners (|p - x|
// >= n.(p - x), linear in x), that is n.(p - a) - max(0, n.(b - a), n.(c -
// a)).  closest_on_triangle's regions, taken lane by lane with selects (its
// order of tests, one division a lane), give barycentric weights (u, v) --
// clamped to u, v >= 0, u + v <= 1, which also settles a division by zero --
// of a point x' of the triangle near the closest one, and n = (p - x') / |p -
// x'|, which makes the bound the distance itself up to rounding wherever x'
// is right.  Rounding: p - a, b - a and c - a are rounded (relative 2^-24 a
// coordinate), each dot product with n (three products and two sums: 4.01 *
// 2^-24 * sum |n_i| |y_i| <= 4.01 * 2^-24 * |n| |y|), the difference and the
// max (2^-24 of the result), and 1 / |n| by rsqrt of the rounded n.n (at most
// 8 * 2^-24 relative): in all under 14 * 2^-24 * (|p - a| + max(|b - a|, |c -
// a|)), and each length is at most its L1 norm; 2^-20 of that sum of L1 norms
// is taken off.  A lane with n = 0 (p on the triangle) gets 0; NaNs (from
// overflow) compare false, and the walks visit such lanes.
//
// The upper bound is |p - x'| itself: the rounded n differs from p - x' (x'
// with the rounded weights, on the triangle up to u + v <= 1 + 2^-24) by at
// most some 5 * 2^-24 * (|p - a| + |b - a| + |c - a|), and sqrt(n.n) from |n|
// by 2 * 2^-24 relative: 2^-20 of that sum of L1 norms, and of |n|, is added.
// It bounds the exact distance; the double precision one lies within some
// ulps of the coordinates of that, far below the tie slack (POINT_TIE_SLACK)
// that the walks add to it.
//
// The body below takes the edges apx .. acz (ap = p - a, ab = b - a, ac = c -
// a) of type V (lanes) or E (one value for all lanes) and declares `lower`
// and `upper` (V); IV: V's comparison type.  The corners' dot products come
// from the edges' (b - p = (a - p) + (b - a)): some 130 operations.
#define POINT_TRIANGLE_BOUNDS(V, IV, E)                                                                 \
    /* closest_on_triangle's d1 .. d6: ab.ap, ac.ap, ab.bp, ac.bp, ab.cp, ac.cp */                      \
    const V d1 = abx * apx + aby * apy + abz * apz, d2 = acx * apx + acy * apy + acz * apz;             \
    const E ab2 = abx * abx + aby * aby + abz * abz, ac2 = acx * acx + acy * acy + acz * acz;           \
    const E abac = abx * acx + aby * acy + abz * acz;                                                   \
    const V d3 = d1 - ab2, d4 = d2 - abac, d5 = d1 - abac, d6 = d2 - ac2;                               \
    const V vc = d1 * d4 - d3 * d2, vb = d5 * d2 - d1 * d6, va = d3 * d6 - d5 * d4;                    \
    /* (u, v) = (u_num, v_num) / den, region by region, the first of closest_on_triangle's tests */    \
    /* that holds winning: set in reverse order */                                                      \
    V u_num = vb, v_num = vc, den = va + vb + vc;                              /* the face */           \
    const V e_bc = d4 - d3, f_bc = d5 - d6;                                                             \
    const IV on_bc = (va <= 0.0f) & (e_bc >= 0.0f) & (f_bc >= 0.0f);                                    \
    u_num = select(u_num, f_bc, on_bc);                                                                 \
    v_num = select(v_num, e_bc, on_bc);                                                                 \
    den = select(den, e_bc + f_bc, on_bc);                                                              \
    const IV on_ac = (vb <= 0.0f) & (d2 >= 0.0f) & (d6 <= 0.0f);                                        \
    u_num = select(u_num, (V)(0.0f), on_ac);                                                            \
    v_num = select(v_num, d2, on_ac);                                                                   \
    den = select(den, d2 - d6, on_ac);                                                                  \
    const IV at_c = (d6 >= 0.0f) & (d5 <= d6);                                                          \
    u_num = select(u_num, (V)(0.0f), at_c);                                                             \
    v_num = select(v_num, (V)(1.0f), at_c);                                                             \
    den = select(den, (V)(1.0f), at_c);                                                                 \
    const IV on_ab = (vc <= 0.0f) & (d1 >= 0.0f) & (d3 <= 0.0f);                                        \
    u_num = select(u_num, d1, on_ab);                                                                   \
    v_num = select(v_num, (V)(0.0f), on_ab);                                                            \
    den = select(den, d1 - d3, on_ab);                                                                  \
    const IV at_b = (d3 >= 0.0f) & (d4 <= d3);                                                          \
    u_num = select(u_num, (V)(1.0f), at_b);                                                             \
    v_num = select(v_num, (V)(0.0f), at_b);                                                             \
    den = select(den, (V)(1.0f), at_b);                                                                 \
    const IV at_a = (d1 <= 0.0f) & (d2 <= 0.0f);                                                        \
    u_num = select(u_num, (V)(0.0f), at_a);                                                             \
    v_num = select(v_num, (V)(0.0f), at_a);                                                             \
    den = select(den, (V)(1.0f), at_a);                                                                 \
    const V inv = 1.0f / den;                                                                           \
    const V u = fmin(fmax(u_num * inv, 0.0f), 1.0f);                  /* fmax takes NaN to 0 */        \
    const V v = fmin(fmax(v_num * inv, 0.0f), 1.0f - u);                                                \
    /* n = p - x' = ap - u ab - v ac */                                                                 \
    const V nx = apx - u * abx - v * acx, ny = apy - u * aby - v * acy, nz = apz - u * abz - v * acz;  \
    const V s_ap = nx * apx + ny * apy + nz * apz, s_ab = nx * abx + ny * aby + nz * abz;               \
    const V s_ac = nx * acx + ny * acy + nz * acz;                                                      \
    const V n2 = nx * nx + ny * ny + nz * nz;                                                           \
    const V l_ap = fabs(apx) + fabs(apy) + fabs(apz);                                                   \
    const E l_ab = fabs(abx) + fabs(aby) + fabs(abz), l_ac = fabs(acx) + fabs(acy) + fabs(acz);         \
    const V lower = select((s_ap - fmax(fmax(s_ab, s_ac), 0.0f)) * rsqrt(n2)                            \
                           - 0x1p-20f * (l_ap + fmax(l_ab, l_ac)), (V)(0.0f), n2 == 0.0f);              \
    const V upper = sqrt(n2) * (1.0f + 0x1p-20f) + 0x1p-20f * (l_ap + l_ab + l_ac)

// Lower bounds of the distances from p to the four triangles of a packet
// (POINT_TRIANGLE_BOUNDS; walk_wide_points).
__attribute__((always_inline))
inline float4 packet_distance_bounds(__global const TrianglePacket* t, float3 p)
{
    const float4 apx = p.x - t->v0[0], apy = p.y - t->v0[1], apz = p.z - t->v0[2];
    const float4 abx = t->v1[0] - t->v0[0], aby = t->v1[1] - t->v0[1], abz = t->v1[2] - t->v0[2];
    const float4 acx = t->v2[0] - t->v0[0], acy = t->v2[1] - t->v0[1], acz = t->v2[2] - t->v0[2];
    POINT_TRIANGLE_BOUNDS(float4, int4, float4);
    (void)upper;
    return lower;
}

// x rounded up to float32.
inline float float_up(point_real x)
{
    const float f = (float)x;
    return (point_real)f >= x ? f : nextafter(f, INFINITY);
}

// The WideDisks of the wide BVH (clrt/accel/disks.py), one a node, which the
// point queries' copy of it holds between its nodes and its packets
// (geometry.cl): as many bytes as the nodes.
inline __global const WideDisk* wide_disks(const Geometry* g)
{
    const size_t nodes_bytes = ((__global const uchar*)g->packets - (__global const uchar*)g->wide_nodes) / 2;
    return (__global const WideDisk*)((__global const uchar*)g->wide_nodes + nodes_bytes);
}

// closest_point's walk over the wide BVH: as the binary one, children within
// the best distance plus `margin` taken nearest first, a leaf's triangles
// through packet_distance_bounds.  A child's distance: the larger of those to
// its box and to its disk (WideDisk: with v = p - c, h = n.v and l the length
// of v - h n, the hypotenuse of |h| - half_height and l - radius, each at
// least 0), both lower bounds of the distance to its triangles, eight
// children in float8.  Their rounding (some 20 * 2^-24 of |p - c| for the disk, with
// |n| within 2^-23 of 1) stays far within the margin (2^-16 of the largest
// coordinate, at least 2^-17 |p - c|).
inline void walk_wide_points(const Geometry* g, float3 p, float margin, PointHit* best)
{
    const point_real3 pr = TO_POINT_REAL3(p);
    const point_real tie = POINT_TIE_SLACK(margin);
    __global const WideDisk* disks = wide_disks(g);
    int2 stack[WIDE_STACK_SIZE];       // (node or first packet, packet count: 0 for a node)
    float stack_d[WIDE_STACK_SIZE];    // the lower bound of its distance
    int sp = 0;
    int2 current = (int2)(0, 0);       // the root node
    for (;;) {
        if (current.y > 0) {
            for (int k = current.x; k < current.x + current.y; ++k) {
                __global const TrianglePacket* t = g->packets + k;
                const float4 lower = packet_distance_bounds(t, p);
                // the lanes at or below the best distance (plus the slack) rounded up to float32, but
                // the best triangle itself (visited: the seed, often), then each against the best as it
                // is when its turn comes
                const float near = float_up(best->dist + tie);
                int4 visit = (t->slot >= 0) & (t->slot != best->slot) & !(lower > near);
                for (int lane = 0; lane < 4; ++lane)
                    if (visit[lane] && !((point_real)lower[lane] > best->dist + tie))
                        visit_point_triangle(g, pr, 0, t->slot[lane], best);
            }
        } else {
            __global const BvhWideNode* n = g->wide_nodes + current.x;
            const float8 dx = fmax(fmax(n->lo_x - p.x, p.x - n->hi_x), 0.0f);
            const float8 dy = fmax(fmax(n->lo_y - p.y, p.y - n->hi_y), 0.0f);
            const float8 dz = fmax(fmax(n->lo_z - p.z, p.z - n->hi_z), 0.0f);
            __global const WideDisk* disk = disks + current.x;
            const float8 vx = p.x - disk->cx, vy = p.y - disk->cy, vz = p.z - disk->cz;
            const float8 h = vx * disk->nx + vy * disk->ny + vz * disk->nz;
            const float8 lx = vx - h * disk->nx, ly = vy - h * disk->ny, lz = vz - h * disk->nz;
            const float8 across = fmax(fabs(h) - disk->half_height, 0.0f);
            const float8 beside = fmax(sqrt(lx * lx + ly * ly + lz * lz) - disk->radius, 0.0f);
            const float8 d = fmax(dx * dx + dy * dy + dz * dz, across * across + beside * beside);
            const float reach = (float)best->dist + margin;
            uint lanes = lane_bits((n->count >= 0) & (d <= reach * reach));
            if (lanes) {
                __global const int* child = (__global const int*)&n->child;
                __global const int* count = (__global const int*)&n->count;
                int k = 31 - clz(lanes & (0u - lanes));   // the lowest lane left
                lanes &= lanes - 1u;
                if (!lanes) {                             // one child near: no stack
                    current = (int2)(child[k], count[k]);
                    continue;
                }
                // the others onto the stack farthest first (insertion sort), the nearest taken
                const int base = sp;
                for (;;) {
                    const float dk = d[k];
                    int j = sp++;
                    for (; j > base && stack_d[j - 1] < dk; --j) {
                        stack[j] = stack[j - 1];
                        stack_d[j] = stack_d[j - 1];
                    }
                    stack[j] = (int2)(child[k], count[k]);
                    stack_d[j] = dk;
                    if (!lanes)
                        break;
                    k = 31 - clz(lanes & (0u - lanes));
                    lanes &= lanes - 1u;
                }
                current = stack[--sp];
                continue;
            }
        }
        const float reach = (float)best->dist + margin;
        if (!resume_postponed(stack, stack_d, &sp, reach * reach, &current, true))
            break;
    }
}

#endif

#ifdef ACCEL_BVH
// One step of the binary walks (walk_rows_points, closest_point_placed):
// of a row's two children, with lower bounds d_left and d_right of their
// distances, those that exist (count >= 0) within `reach`: the nearer becomes
// *current, the other waits on the stack with its bound.  False when neither
// is within reach (the walk then resumes from the stack).
inline bool enter_nearer_child(int2 left_child, int2 right_child, float d_left, float d_right, float reach,
                               int2* stack, float* stack_d, int* sp, int2* current)
{
    const bool left = left_child.y >= 0 && d_left <= reach;
    const bool right = right_child.y >= 0 && d_right <= reach;
    if (left && right) {
        const bool right_first = d_right < d_left;
        stack[*sp] = right_first ? left_child : right_child;
        stack_d[*sp] = right_first ? d_left : d_right;
        ++*sp;
        *current = right_first ? right_child : left_child;
        return true;
    }
    if (left || right) {
        *current = left ? left_child : right_child;
        return true;
    }
    return false;
}

// The binary walk of one tree from row `root` (the one-level walk; in a
// two-level scene a mesh's own, in its space: instance -1, the triangles as
// they are stored, for the signs by normal), nearest children first, into
// *best.
__attribute__((always_inline))
inline void walk_rows_points(const Geometry* g, float3 p, int root, int instance, float margin, PointHit* best)
{
    const point_real3 pr = TO_POINT_REAL3(p);
    int2 stack[BVH_STACK_SIZE];        // (row or first slot, leaf count: 0 for a row)
    float stack_d[BVH_STACK_SIZE];     // the lower bound of its distance
    int sp = 0;
    int2 current = (int2)(root, 0);
    for (;;) {
        if (current.y > 0) {
            for (int s = current.x; s < current.x + current.y; ++s)
                visit_point_triangle(g, pr, instance, s, best);
        } else {
            const BvhPairNode n = *SPLIT_AT(g, nodes, current.x);
            const int2 left_child = PAIR_LEFT(n), right_child = PAIR_RIGHT(n);
            const float d_left = left_child.y >= 0 ? point_bound(p, n.left_a, n.left_b) : INFINITY;
            const float d_right = right_child.y >= 0 ? point_bound(p, n.right_a, n.right_b) : INFINITY;
            if (enter_nearer_child(left_child, right_child, d_left, d_right, (float)best->dist + margin, stack,
                                   stack_d, &sp, &current))
                continue;
        }
        if (!resume_postponed(stack, stack_d, &sp, (float)best->dist + margin, &current, true))
            break;
    }
}
#endif

#ifdef ACCEL_INSTANCES
// A two-level scene's closest point (docs/instances.md): one walk, one stack
// over both levels, as accel_bvh.cl's walk_instances.  Distances are the
// world's throughout: every triangle is measured as its instance places it
// (visit_point_triangle), and a mesh's volumes, tested in its own space
// against the point moved there, count their lower bound times the
// instance's smallest scale (Instance.min_scale: no point of the placed
// volume lies nearer), less a slack for the move's and the bound's rounding:
// 2^-16 of the object point's size and distance, times the map's condition
// number, mapped back by its largest scale -- so that no triangle brute force
// could pick is passed by, for any affine map.
#define LEAVE_INSTANCE_POINT (-2)

inline void closest_point_placed(const Geometry* g, float3 p, float margin, PointHit* best)
{
    const point_real3 pr = TO_POINT_REAL3(p);
#ifdef ACCEL_BVH
    int2 stack[BVH_STACK_SIZE];
    float stack_d[BVH_STACK_SIZE];     // lower bounds of world distances
    int sp = 0;
    int2 current = (int2)(0, 0);
    int instance = -1;                 // the instance walked (-1: the top level)
    float3 q = p;                      // the point in the space walked
    float scale = 1.0f, slack_scale = 0.0f, slack_base = 0.0f;
    for (;;) {
        if (current.y > 0 && instance < 0) {          // a top-level leaf: enter its instance
            instance = current.x;
            __global const Instance* in = SPLIT_AT(g, instances, instance);
            q = object_point(in, p);
            float norm_a = 0.0f, norm_b = 0.0f;
            for (int i = 0; i < 3; ++i) {
                norm_a = fmax(norm_a, fabs(in->to_world[i].x) + fabs(in->to_world[i].y) + fabs(in->to_world[i].z));
                norm_b = fmax(norm_b, fabs(in->to_object[i].x) + fabs(in->to_object[i].y)
                                      + fabs(in->to_object[i].z));
            }
            scale = in->min_scale;
            slack_scale = 0x1p-16f * norm_a * norm_a * norm_b;
            slack_base = slack_scale * fmax(fmax(fabs(q.x), fabs(q.y)), fabs(q.z));
            stack[sp] = (int2)(0, LEAVE_INSTANCE_POINT);
            stack_d[sp] = -INFINITY;
            ++sp;
            current = (int2)(in->root, 0);
            continue;
        }
        if (current.y > 0) {
            for (int s = current.x; s < current.x + current.y; ++s)
                visit_point_triangle(g, pr, instance, s, best);
        } else if (current.y == LEAVE_INSTANCE_POINT) {
            instance = -1;
            q = p;
            scale = 1.0f;
            slack_scale = slack_base = 0.0f;
        } else {
            const BvhPairNode n = *SPLIT_AT(g, nodes, current.x);
            const int2 left_child = PAIR_LEFT(n), right_child = PAIR_RIGHT(n);
            float d_left = INFINITY, d_right = INFINITY;
            if (left_child.y >= 0) {
                const float d = point_bound(q, n.left_a, n.left_b);
                d_left = scale * d - (slack_base + slack_scale * d);
            }
            if (right_child.y >= 0) {
                const float d = point_bound(q, n.right_a, n.right_b);
                d_right = scale * d - (slack_base + slack_scale * d);
            }
            if (enter_nearer_child(left_child, right_child, d_left, d_right, (float)best->dist + margin, stack,
                                   stack_d, &sp, &current))
                continue;
        }
        if (!resume_postponed(stack, stack_d, &sp, (float)best->dist + margin, &current, true))
            break;
    }
#else
    for (uint i = 0; i < g->num_instances; ++i) {
        __global const Instance* in = SPLIT_AT(g, instances, i);
        for (int s = in->first; s < in->first + in->count; ++s)
            visit_point_triangle(g, pr, (int)i, s, best);
    }
#endif
}
#endif

#include "point_warp.cl"

// The nearest triangle to p (device frame) within max_dist (inclusive);
// prim -1 when none is.  `margin`: POINT_MARGIN.  `seed`: a slot to visit
// before the walk (-1: none) -- the nearest triangle of a point close by,
// whose distance then prunes the walk from its start.  Any triangle visited
// more (or first) changes no answer: the best is the least (distance, input
// index) of those visited, and every walk visits all that could be it.
inline PointHit no_point_hit(float max_dist)
{
    PointHit best;
    best.prim = -1;
    best.dist = max_dist;
    best.point = (point_real3)(0);
    best.u = 0.0f;
    best.v = 0.0f;
    best.slot = -1;
    best.feature = FEATURE_FACE;
    best.instance = 0;
    return best;
}

inline PointHit closest_point(const Geometry* g, float3 p, float max_dist, float margin, int seed)
{
    PointHit best = no_point_hit(max_dist);
    const point_real3 pr = TO_POINT_REAL3(p);
#ifdef ACCEL_INSTANCES
    closest_point_placed(g, p, margin, &best);   // (a seed slot names no instance: not taken)
#else
    if (seed >= 0)
        visit_point_triangle(g, pr, 0, seed, &best);
#endif
#if defined(ACCEL_INSTANCES)
#elif defined(ACCEL_BVH) && defined(BVH_WIDE)
    walk_wide_points(g, p, margin, &best);
#elif defined(ACCEL_BVH)
    walk_rows_points(g, p, 0, 0, margin, &best);
#else
    for (uint i = 0; i < g->num_tris; ++i)
        visit_point_triangle(g, pr, 0, (int)i, &best);
#endif
    return best;
}

// The closest point of a work-item's point p, if `taken` (a point there, and
// valid), as closest_point finds it (from triangle `seed` first); else none
// (prim -1).  Where the warp walks together (WARP_WALKS, point_warp.cl)
// every work-item of the warp must call it.
inline PointHit closest_point_item(const Geometry* g, float3 p, bool taken, float max_dist, float margin, int seed)
{
#if WARP_WALKS
    PointHit best = no_point_hit(max_dist);
    if (taken && seed >= 0)
        visit_point_triangle(g, TO_POINT_REAL3(p), 0, seed, &best);
    warp_closest_walk(g, p, taken, margin, &best);
    return best;
#else
    return taken ? closest_point(g, p, max_dist, margin, seed) : no_point_hit(max_dist);
#endif
}

// ---- The sign rules of signed distances (trace.cl's query_signed_distance_*;
// "winding" is winding.cl's).

// Inside by the pseudo-normal at the closest point (Baerentzen and Aanaes
// 2005, "Signed distance computation using the angle weighted pseudonormal"):
// p lies inside where it lies behind the normal of the feature holding its
// closest point -- the face's own normal, or the PseudoNormals (layouts.h, by
// slot) of the edge or corner, which weigh every face around it so that the
// faces sharing the point agree.  Exact for closed, consistently wound
// meshes; a point on the surface is outside.
inline bool inside_by_normal(const Geometry* g, __global const PseudoNormals* normals, const PointHit* best,
                             float3 p)
{
    point_real3 n;
    if (best->feature == FEATURE_FACE) {
        __global const TriangleVerts* t = SPLIT_AT(g, tris, best->slot);
        const point_real3 a = TO_POINT_REAL3(t->v0.xyz);
        n = cross(TO_POINT_REAL3(t->v1.xyz) - a, TO_POINT_REAL3(t->v2.xyz) - a);
    } else if (best->feature >= FEATURE_EDGE) {
        n = TO_POINT_REAL3(normals[best->slot].edge[best->feature - FEATURE_EDGE].xyz);
    } else {
        n = TO_POINT_REAL3(normals[best->slot].vertex[best->feature - FEATURE_VERTEX].xyz);
    }
    return dot(TO_POINT_REAL3(p) - best->point, n) < 0;
}

#ifdef ACCEL_INSTANCES
// Is instance `in`'s map a similarity -- a rotation, perhaps a mirror, and one
// scale: A^T A a multiple of the identity to within 2^-16 (the float32
// rounding of the map, and room)?
inline bool similar_placement(__global const Instance* in)
{
    __global const float4* m = in->to_world;
    const float3 c0 = (float3)(m[0].x, m[1].x, m[2].x), c1 = (float3)(m[0].y, m[1].y, m[2].y);
    const float3 c2 = (float3)(m[0].z, m[1].z, m[2].z);
    const float xx = dot(c0, c0), yy = dot(c1, c1), zz = dot(c2, c2);
    const float s2 = (xx + yy + zz) / 3.0f;
    const float off = fmax(fmax(fabs(dot(c0, c1)), fabs(dot(c0, c2))), fabs(dot(c1, c2)));
    return fmax(fmax(fmax(fabs(xx - s2), fabs(yy - s2)), fabs(zz - s2)), off) <= 0x1p-16f * s2;
}

// inside_by_normal in a two-level scene: p (world) and its closest point
// `best`, on instance best->instance.  A face's normal is the placed
// triangle's as wound (instance_normal: a mirror's turned over).  An edge's or
// a corner's pseudo-normal stays one under a similarity -- turned by the
// inverse transpose, negated in a mirror: each face's normal turns so and the
// angles that weigh them stay.  An uneven scale or a shear changes the angles
// and the faces' weights, and the mapped pseudo-normal can point wrong beside
// a sharp edge or corner; there the rule is asked in the mesh's own space: the
// closest point of the point moved there and its feature's own pseudo-normal
// (an affine map keeps the side of a closed surface a point lies on; a mirror
// turns the wound side over).
inline bool inside_by_placed_normal(const Geometry* g, __global const PseudoNormals* normals, const PointHit* best,
                                    float3 p)
{
    __global const Instance* in = SPLIT_AT(g, instances, best->instance);
    point_real3 n;
    if (best->feature == FEATURE_FACE) {
        n = TO_POINT_REAL3(instance_normal(in, SPLIT_AT(g, tris, best->slot)));
    } else if (similar_placement(in)) {
        const float4 m = best->feature >= FEATURE_EDGE ? normals[best->slot].edge[best->feature - FEATURE_EDGE]
                                                       : normals[best->slot].vertex[best->feature - FEATURE_VERTEX];
        n = TO_POINT_REAL3(world_normal(in, m.xyz));
        if (mirrored(in))
            n = -n;
    } else {
        const float3 q = object_point(in, p);
        PointHit here = no_point_hit(INFINITY);
#ifdef ACCEL_BVH
        // The margin from a box that holds the mesh in its space: the instance's world box mapped back.
        const float3 mid = object_point(in, 0.5f * (in->lo.xyz + in->hi.xyz));
        const float3 extent = 0.5f * (in->hi.xyz - in->lo.xyz);
        __global const float4* b = in->to_object;
        const float3 reach = (float3)(dot(fabs(b[0].xyz), extent), dot(fabs(b[1].xyz), extent),
                                      dot(fabs(b[2].xyz), extent));
        walk_rows_points(g, q, in->root, -1, POINT_MARGIN(q, mid - reach, mid + reach), &here);
#else
        for (int s = in->first; s < in->first + in->count; ++s)
            visit_point_triangle(g, TO_POINT_REAL3(q), -1, s, &here);
#endif
        return inside_by_normal(g, normals, &here, q) != mirrored(in);
    }
    return dot(TO_POINT_REAL3(p) - best->point, n) < 0;
}
#endif

// Inside by ray parity: p lies inside where a ray from it crosses the surface
// an odd number of times (any winding, closed meshes).  A ray through an edge
// or a corner meets every triangle there (triangle.cl's watertight test), so
// one direction can count a crossing twice: three fixed directions, in no
// plane of a grid or an axis, vote, and two of three decide.  A point outside
// the box of the triangles (lo .. hi) is outside without a ray: so no ray
// starts beyond the triangle test's float32 reach (clrt/device/reach.py).
#define PARITY_DIRECTIONS 3
__constant float PARITY_DIRECTION[PARITY_DIRECTIONS][3] = {
    {0.265299859f, 0.851599549f, 0.452099760f},
    {-0.768079281f, 0.179495158f, -0.614683419f},
    {0.431073572f, -0.625361660f, 0.650460122f},
};

inline bool inside_by_parity(const Geometry* g, float3 p, float3 lo, float3 hi)
{
    if (any(p < lo) || any(p > hi))
        return false;
    int odd = 0;
    for (int k = 0; k < PARITY_DIRECTIONS; ++k) {
        HitSink counter;   // counts only: no output arrays
        counter.ray_ids = 0;
        counter.prims = 0;
        counter.ts = 0;
        counter.instances = 0;
        counter.next = 0;
        counter.capacity = 0u;
        counter.ray = 0;
        counter.count = 0u;
        counter.cull = CULL_NONE;
        const float3 dir = (float3)(PARITY_DIRECTION[k][0], PARITY_DIRECTION[k][1], PARITY_DIRECTION[k][2]);
        query_hits(g, p, dir, 0.0f, INFINITY, QUERY_ALL, false, &counter);
        odd += (int)(counter.count & 1u);
    }
    return 2 * odd > PARITY_DIRECTIONS;
}

#endif
