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
// clouds"): each child of a row carries the first three terms of the Taylor
// series of its triangles' solid angles about their centre (a WindingNode,
// layouts.h: the dipole, and the first and second moments of the normals),
// and the walk takes a child whose every corner lies within its radius r of
// the centre, while p lies farther than WINDING_BETA r from it, from that
// series instead of opening it; the rest it opens, down to exact leaves.
// The series' error falls as (r / distance)^3 times the child's own solid
// angle, and the errors of many children partly cancel: WINDING_BETA = 6
// kept the largest error of 200 points in and around each of seven scans (4k
// to 75k triangles, device-built trees) at 2.1e-5 and of the tests' meshes at
// 1e-5, against the exact sum (clrt.query.results.WINDING_NUMBER_ERROR is
// 1e-4; tests/test_inside.py).  On one of those scans (cow, a host SAH tree)
// 2, Barill's choice, gave 5.6e-3, and 4 gave 1.8e-4 -- 4.2e-3 without the
// series' last term.  Without a BVH every triangle is summed exactly.
#ifndef CLRT_WINDING_CL
#define CLRT_WINDING_CL

#include "geometry.cl"
#include "point.cl"

#define WINDING_BETA 6.0
#define INV_4PI 0.07957747154594767

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

// The series of a WindingNode at p, times 4 pi: with r = centre - p, R = |r|,
// N the dipole, M the first moment and T the second,
//   N.r / R^3
// + (tr M - 3 r.M r / R^2) / R^3
// + (15 T[r, r, r] / R^4 - 3 (2 r.u + r.w) / R^2) / (2 R^3),
// u_k = sum_i T[i][i][k], w_i = sum_j T[i][j][j]: the three terms of
// integral n . (x - p) / |x - p|^3 dA with (x - p) / |x - p|^3 expanded about
// the centre (its first and second derivatives contracted with the moments).
inline point_real far_field(__global const WindingNode* node, point_real3 r, point_real r2)
{
    const point_real inv_r2 = 1 / r2;
    const point_real inv_r3 = inv_r2 / sqrt(r2);
    __global const float* m = node->first;
    __global const float* t = node->second;
    const point_real3 N = TO_POINT_REAL3(node->normal.xyz);
    const point_real3 Mr = (point_real3)(m[0] * r.x + m[1] * r.y + m[2] * r.z,
                                         m[3] * r.x + m[4] * r.y + m[5] * r.z,
                                         m[6] * r.x + m[7] * r.y + m[8] * r.z);
    const point_real trace_m = (point_real)m[0] + m[4] + m[8];
    point_real rrr = 0;   // T[r, r, r]
    for (int i = 0; i < 3; ++i) {
        __global const float* ti = t + 6 * i;
        const point_real q = ti[0] * r.x * r.x + ti[3] * r.y * r.y + ti[5] * r.z * r.z
                           + 2 * (ti[1] * r.x * r.y + ti[2] * r.x * r.z + ti[4] * r.y * r.z);
        rrr += (i == 0 ? r.x : (i == 1 ? r.y : r.z)) * q;
    }
    const point_real3 u = (point_real3)(t[0] + t[7] + t[14], t[1] + t[9] + t[16], t[2] + t[10] + t[17]);
    const point_real3 w = (point_real3)(t[0] + t[3] + t[5], t[6] + t[9] + t[11], t[12] + t[15] + t[17]);
    const point_real order0 = dot(N, r);
    const point_real order1 = trace_m - 3 * dot(r, Mr) * inv_r2;
    const point_real order2 = (15 * rrr * inv_r2 * inv_r2 - 3 * (2 * dot(r, u) + dot(r, w)) * inv_r2) / 2;
    return (order0 + order1 + order2) * inv_r3;
}

// The winding number of the mesh at p (device frame); `winding`: the
// WindingNodes of the rows (unused without a BVH).
inline point_real winding_number(const Geometry* g, __global const WindingNode* winding, float3 p)
{
    const point_real3 pr = TO_POINT_REAL3(p);
    point_real sum = 0;
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
            const point_real3 r = TO_POINT_REAL3(node->centre.xyz) - pr;
            const point_real r2 = dot(r, r);
            const point_real reach = WINDING_BETA * node->centre.w;
            if (r2 > reach * reach)
                sum += far_field(node, r, r2);
            else if (child.y > 0)
                sum += leaf_solid_angle(g, pr, child.x, child.y);
            else if (next < 0)
                next = child.x;
            else
                stack[sp++] = child.x;
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
    return sum * INV_4PI;
}

// ---- The WindingNodes of a tree, made level by level from the deepest up
// (trace.cl's winding_nodes): a leaf child's from its triangles, an inner
// child's from its row's two, so that each level reads only finished ones.
// Sums in double precision where the device has it; the centre is rounded to
// float32 first and every moment taken about the rounded one.

// The float32 radius of a child from its double one: rounded up.
inline float radius_up(point_real r)
{
    const float f = (float)r;
    return (point_real)f >= r ? f : nextafter(f, INFINITY);
}

// The WindingNode of the triangles in slots first .. first + count - 1.
inline WindingNode leaf_winding_node(const Geometry* g, int first, int count)
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
    // Triangles of no area: any centre serves (their series is zero), the mean of their centroids.
    const float3 centre = convert_float3(area > 0 ? weighted / area : mean / count);
    const point_real3 cr = TO_POINT_REAL3(centre);
    WindingNode node;
    point_real3 dipole = (point_real3)(0);
    point_real m[9] = {0, 0, 0, 0, 0, 0, 0, 0, 0};
    point_real sec[18] = {0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0};
    point_real radius2 = 0;
    for (int s = first; s < first + count; ++s) {
        __global const TriangleVerts* t = SPLIT_AT(g, tris, s);
        const point_real3 d0 = TO_POINT_REAL3(t->v0.xyz) - cr, d1 = TO_POINT_REAL3(t->v1.xyz) - cr;
        const point_real3 d2 = TO_POINT_REAL3(t->v2.xyz) - cr;
        radius2 = fmax(radius2, fmax(dot(d0, d0), fmax(dot(d1, d1), dot(d2, d2))));
        const point_real3 va = cross(d1 - d0, d2 - d0) / 2;   // area times the unit normal
        const point_real3 sum = d0 + d1 + d2;
        dipole += va;
        const point_real vi[3] = {va.x, va.y, va.z};
        const point_real di[3] = {sum.x / 3, sum.y / 3, sum.z / 3};
        // integral of d_j d_k over the triangle, over its area: (sum of the
        // corners' d_j d_k + (sum d)_j (sum d)_k) / 12
        const point_real x0[3] = {d0.x, d0.y, d0.z}, x1[3] = {d1.x, d1.y, d1.z}, x2[3] = {d2.x, d2.y, d2.z};
        const point_real sx[3] = {sum.x, sum.y, sum.z};
        for (int i = 0; i < 3; ++i) {
            for (int j = 0; j < 3; ++j)
                m[3 * i + j] += vi[i] * di[j];
            int jk = 0;
            for (int j = 0; j < 3; ++j)
                for (int k = j; k < 3; ++k, ++jk)
                    sec[6 * i + jk] += vi[i] * (x0[j] * x0[k] + x1[j] * x1[k] + x2[j] * x2[k] + sx[j] * sx[k]) / 12;
        }
    }
    node.centre = (float4)(centre, radius_up(sqrt(radius2)));
    node.normal = (float4)(convert_float3(dipole), (float)area);
    for (int k = 0; k < 9; ++k)
        node.first[k] = (float)m[k];
    for (int k = 0; k < 18; ++k)
        node.second[k] = (float)sec[k];
    node.pad = 0.0f;
    return node;
}

// The WindingNode of two children joined (an inner child: its row's two
// WindingNodes, `a` and `b`): moments moved to the joint centre (with
// e = child centre - joint centre, d = d' + e) and summed, the radius the
// farthest child's reach.
inline WindingNode joined_winding_node(__global const WindingNode* a, __global const WindingNode* b)
{
    const point_real area_a = a->normal.w, area_b = b->normal.w;
    const point_real3 ca = TO_POINT_REAL3(a->centre.xyz), cb = TO_POINT_REAL3(b->centre.xyz);
    const point_real area = area_a + area_b;
    const float3 centre = convert_float3(area > 0 ? (area_a * ca + area_b * cb) / area : (ca + cb) / 2);
    const point_real3 cr = TO_POINT_REAL3(centre);
    WindingNode node;
    point_real radius = 0;
    point_real3 dipole = (point_real3)(0);
    point_real m[9] = {0, 0, 0, 0, 0, 0, 0, 0, 0};
    point_real sec[18] = {0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0};
    for (int c = 0; c < 2; ++c) {
        __global const WindingNode* child = c == 0 ? a : b;
        const point_real3 e3 = TO_POINT_REAL3(child->centre.xyz) - cr;
        radius = fmax(radius, sqrt(dot(e3, e3)) + child->centre.w);
        const point_real3 n3 = TO_POINT_REAL3(child->normal.xyz);
        dipole += n3;
        const point_real e[3] = {e3.x, e3.y, e3.z}, n[3] = {n3.x, n3.y, n3.z};
        // first: M_ij + N_i e_j; second: T_ijk + M_ij e_k + M_ik e_j + N_i e_j e_k
        for (int i = 0; i < 3; ++i) {
            for (int j = 0; j < 3; ++j)
                m[3 * i + j] += child->first[3 * i + j] + n[i] * e[j];
            int jk = 0;
            for (int j = 0; j < 3; ++j)
                for (int k = j; k < 3; ++k, ++jk)
                    sec[6 * i + jk] += child->second[6 * i + jk] + child->first[3 * i + j] * e[k]
                                     + child->first[3 * i + k] * e[j] + n[i] * e[j] * e[k];
        }
    }
    node.centre = (float4)(centre, radius_up(radius));
    node.normal = (float4)(convert_float3(dipole), (float)area);
    for (int k = 0; k < 9; ++k)
        node.first[k] = (float)m[k];
    for (int k = 0; k < 18; ++k)
        node.second[k] = (float)sec[k];
    node.pad = 0.0f;
    return node;
}

#endif
