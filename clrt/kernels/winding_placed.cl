// Winding numbers of a two-level scene (-DACCEL_INSTANCES, docs/instances.md):
// a part of winding.cl, included there after the solid angles and the series
// it shares, before the walks that use it.
//
// The scene's w(p) is the sum over its instances of each placed mesh's: every
// triangle as its instance places it.  A leaf's triangles are summed exactly,
// their corners mapped into the world (in double precision where the device
// has it): wound as the world sees them, a mirror's too.
//
// Far fields.  A mesh's PlacedWindingNodes are made once, in its own space,
// and serve every placement of it.  A placement x' = A x + b maps the vector
// area n dA to cof(A) n dA (cof(A) = det(A) A^-T: a mirror turns it over) and
// x - c to A (x - c).  With q = A^-1 (p - b) the point in the mesh's space,
// r = c - q, G = A^T A, w = G r and R^2 = |A r|^2 = r.w (the world's distance
// squared), the world's series of the mapped moments (winding.cl's far_field)
// is det(A) times
//   N.r / R^3 + (tr M - 3 r.M w / R^2) / R^3
//   + (15 T[r, w, w] / R^2 - 3 (2 t.w + sum_l r_l T_l : G)) / (2 R^5),
// t_k = sum_l T[l][l][k]: each contraction of world tensors with world vectors
// written in the mesh's space (cof(A)^T A = det(A) I, A^T A = G).  The whole
// moments M[i][j] and T[i][j][k] are needed, not their symmetric parts alone:
// cof(A) and A mix them differently unless A is a similarity.  This is the
// world's series itself, so the world's rule holds: a child is taken from it
// where R exceeds beta times its world radius, bounded by the lesser of its
// radius times the map's largest scale (bounded from G, map_scales: exact for
// a similarity and for one scale apart) and its box (half-extents about the
// centre, PlacedWindingNode.extent) mapped -- a child lying across an uneven
// map's stretch is placed smaller than the largest scale says --; its error
// bound is the world's (remainder_bound, the world's area and radius bounded
// so).  A leaf under a similarity sums its mesh's own solid angles at q (a
// mirror turns them over).  The top level's rows hold the world's far fields
// -- an instance's is its mesh's root mapped by its transform --, so an
// instance far from p costs one series, not a walk.
//
// Rounding.  The stored moments are float32, and mapped, an entry's rounding
// grows against the world's terms with the map's condition number c: bounded
// term by term (|r| <= R / sigma_3, |w| <= sigma_1^2 |r|, the world's area at
// least sigma_2 sigma_3 times the mesh's), a node's error is some 2^-24 (1 +
// c q)^2 of sigma_1 sigma_2 A / R^2 (q = world radius / R), and the sum over
// the far nodes some 2^-24 c^3 q^2 of the world's solid angles they span:
// within WINDING_NUMBER_ERROR for c up to WINDING_PLACED_CONDITION (32: 5e-5
// at the worst, a hundredth of that measured on bunny00 up to c = 96).  A
// placement conditioned worse is summed exactly, leaf by leaf, and its world
// far field is never taken (radius INFINITY).  R^2 is |A r|^2, not r.G r,
// whose terms would cancel down to c^2 2^-24 of it.
#ifndef CLRT_WINDING_PLACED_CL
#define CLRT_WINDING_PLACED_CL

#include "geometry.cl"
#include "instances.cl"
#include "point.cl"

#ifdef ACCEL_INSTANCES

#define WINDING_PLACED_CONDITION 32.0f

// The space a walk is in: the world (the top level's rows) or an instance's
// mesh's own, with what its map A to the world does to the series.
typedef struct {
    point_real3 q;        // the point in this space
    float g[6];           // G = A^T A: xx, xy, xz, yy, yz, zz (the identity in the world)
    float det;            // det(A) (1 in the world)
    float scale;          // a bound of A's largest scale
    float area;           // a bound of sigma_1 sigma_2, the world's area per unit of this space's
    float condition;      // a bound of A's condition number (the series' rounding grows with it)
    float3 a0, a1, a2;    // A's rows: the world's distance |A r| (r.G r would cancel)
    bool exact;           // no series in this space (conditioned worse than WINDING_PLACED_CONDITION)
    bool similar;         // A a similarity to within 2^-20: a leaf's solid angles are its mesh's own
} WindingSpace;

inline WindingSpace world_space(point_real3 p)
{
    WindingSpace s;
    s.q = p;
    for (int k = 0; k < 6; ++k)
        s.g[k] = (k == 0 || k == 3 || k == 5) ? 1.0f : 0.0f;
    s.det = 1.0f;
    s.scale = 1.0f;
    s.area = 1.0f;
    s.condition = 1.0f;
    s.a0 = (float3)(1.0f, 0.0f, 0.0f);
    s.a1 = (float3)(0.0f, 1.0f, 0.0f);
    s.a2 = (float3)(0.0f, 0.0f, 1.0f);
    s.exact = false;
    s.similar = true;
    return s;
}

// Row i of the linear part of an instance's map (Instance.to_world / to_object).
inline point_real3 map_row(__global const float4* m, int i)
{
    return TO_POINT_REAL3(m[i].xyz);
}

// G = A^T A of to_world's linear part A, its determinant, and bounds of its
// largest scale and its condition number (the smallest scale: min_scale).
inline void map_scales(__global const Instance* in, point_real* g, point_real* det, float* largest, float* condition)
{
    const point_real3 a0 = map_row(in->to_world, 0), a1 = map_row(in->to_world, 1), a2 = map_row(in->to_world, 2);
    const point_real3 c0 = (point_real3)(a0.x, a1.x, a2.x), c1 = (point_real3)(a0.y, a1.y, a2.y);
    const point_real3 c2 = (point_real3)(a0.z, a1.z, a2.z);
    g[0] = dot(c0, c0);
    g[1] = dot(c0, c1);
    g[2] = dot(c0, c2);
    g[3] = dot(c1, c1);
    g[4] = dot(c1, c2);
    g[5] = dot(c2, c2);
    *det = dot(a0, cross(a1, a2));
    // G's largest eigenvalue, sigma_1^2, is at most its largest absolute row
    // sum (Gershgorin: exact for a similarity), and at most its trace less the
    // two others, each at least min_scale^2 (exact for one scale apart).
    const point_real rows = fmax(fabs(g[0]) + fabs(g[1]) + fabs(g[2]),
                                 fmax(fabs(g[1]) + fabs(g[3]) + fabs(g[4]), fabs(g[2]) + fabs(g[4]) + fabs(g[5])));
    const point_real low = in->min_scale;
    const point_real trace = g[0] + g[3] + g[5] - 2 * low * low;
    *largest = 1.0001f * (float)sqrt(fmax(fmin(rows, trace), 0));   // (a margin for the rounding of G, sqrt)
    *condition = *largest / in->min_scale;
}

// The space of instance `in`'s mesh, the world's point p moved into it
// (to_object, in double precision where the device has it, not rounded).
inline WindingSpace instance_space(__global const Instance* in, point_real3 p)
{
    WindingSpace s;
    __global const float4* b = in->to_object;
    s.q = (point_real3)(dot(map_row(b, 0), p) + b[0].w, dot(map_row(b, 1), p) + b[1].w, dot(map_row(b, 2), p) + b[2].w);
    float largest, condition;
    point_real g[6], det;
    map_scales(in, g, &det, &largest, &condition);
    for (int k = 0; k < 6; ++k)
        s.g[k] = (float)g[k];
    s.det = (float)det;
    s.scale = largest;
    s.area = 1.000001f * (float)fabs(det) / in->min_scale;   // sigma_1 sigma_2 = |det| / sigma_3
    s.condition = condition;
    s.a0 = in->to_world[0].xyz;
    s.a1 = in->to_world[1].xyz;
    s.a2 = in->to_world[2].xyz;
    s.exact = condition > WINDING_PLACED_CONDITION;
    const point_real s2 = (g[0] + g[3] + g[5]) / 3;
    s.similar = fmax(fmax(fabs(g[0] - s2), fabs(g[3] - s2)), fmax(fabs(g[5] - s2),
                     fmax(fabs(g[1]), fmax(fabs(g[2]), fabs(g[4]))))) <= 0x1p-20 * s2;
    return s;
}

// A bound of the squared world radius of a child (its radius `radius` and
// half-extents `extent` about its centre, in the space's units) as the
// space's map places it: the sphere's, radius times the largest scale, or
// the box's, the largest of e.G e over its corners e -- at most sum_ij
// |G_ij| extent_i extent_j -- which is tighter where a child lies across an
// uneven map's stretch.
inline float placed_radius2(const WindingSpace* s, float radius, float4 extent)
{
    const float sphere = s->scale * radius;
    if (s->similar)   // (the sphere's is exact)
        return sphere * sphere;
    const float x = extent.x, y = extent.y, z = extent.z;
    const float box = s->g[0] * x * x + s->g[3] * y * y + s->g[5] * z * z
                    + 2.0f * (fabs(s->g[1]) * x * y + fabs(s->g[2]) * x * z + fabs(s->g[4]) * y * z);
    return fmin(sphere * sphere, 1.000001f * box);
}

// G r for G's six entries.
inline float3 times_sym(const float* g, float3 r)
{
    return (float3)(g[0] * r.x + g[1] * r.y + g[2] * r.z, g[1] * r.x + g[3] * r.y + g[4] * r.z,
                    g[2] * r.x + g[4] * r.y + g[5] * r.z);
}

// The series of a PlacedWindingNode over det(A), times 4 pi (see above): r =
// centre - q, w = G r, r2 = |A r|^2; in float32, as winding.cl's far_field.
inline float placed_far_field(__global const PlacedWindingNode* node, float3 r, float3 w, float r2, const float* g)
{
    __global const float* m = node->first;
    __global const float* t = node->second;
    const float inv_r2 = 1.0f / r2;
    const float order0 = dot(node->normal.xyz, r);
    const float3 mw = (float3)(m[0] * w.x + m[1] * w.y + m[2] * w.z, m[3] * w.x + m[4] * w.y + m[5] * w.z,
                               m[6] * w.x + m[7] * w.y + m[8] * w.z);
    const float order1 = m[0] + m[4] + m[8] - 3.0f * dot(r, mw) * inv_r2;
    // T[l] contracted with w (x) w and with G, l = x, y, z: the six entries of
    // each against w's and G's, the off-diagonal ones twice
    const float w0 = w.x * w.x, w1 = 2.0f * w.x * w.y, w2 = 2.0f * w.x * w.z, w3 = w.y * w.y;
    const float w4 = 2.0f * w.y * w.z, w5 = w.z * w.z;
    const float g0 = g[0], g1 = 2.0f * g[1], g2 = 2.0f * g[2], g3 = g[3], g4 = 2.0f * g[4], g5 = g[5];
#define T_DOT(l, a0, a1, a2, a3, a4, a5) (t[6 * (l)] * (a0) + t[6 * (l) + 1] * (a1) + t[6 * (l) + 2] * (a2) \
                                          + t[6 * (l) + 3] * (a3) + t[6 * (l) + 4] * (a4) + t[6 * (l) + 5] * (a5))
    const float t_rww = r.x * T_DOT(0, w0, w1, w2, w3, w4, w5) + r.y * T_DOT(1, w0, w1, w2, w3, w4, w5)
                      + r.z * T_DOT(2, w0, w1, w2, w3, w4, w5);
    const float t_g = r.x * T_DOT(0, g0, g1, g2, g3, g4, g5) + r.y * T_DOT(1, g0, g1, g2, g3, g4, g5)
                    + r.z * T_DOT(2, g0, g1, g2, g3, g4, g5);
#undef T_DOT
    // t_k = T[x][x k] + T[y][y k] + T[z][z k]
    const float3 tk = (float3)(t[0] + t[7] + t[14], t[1] + t[9] + t[16], t[2] + t[10] + t[17]);
    const float order2 = 0.5f * (15.0f * t_rww * inv_r2 - 3.0f * (2.0f * dot(tk, w) + t_g)) * inv_r2;
    return (order0 + order1 + order2) * inv_r2 * rsqrt(r2);
}

// remainder_bound for a child of area `area` and radius `radius` (the
// world's, or bounds of them) at squared distance r2 under a map of
// condition number `condition`: the series' rounding, 2^-12 of A / R^2 there,
// grows here with (1 + condition q)^2 (see above).
inline float placed_remainder_bound(float area, float radius, float r2, float condition)
{
    const float q = radius * rsqrt(r2);
    const float grown = (1.0f + condition * q) * (1.0f + condition * q);
    return 1.001f * area / r2 * (q * q * q * (4.0f - 3.0f * q) / ((1.0f - q) * (1.0f - q)) + 0x1p-12f * grown);
}

// Object point v of instance `in` where it places it, in the world (to_world,
// in double precision where the device has it, not rounded).
inline point_real3 placed_real(__global const Instance* in, float3 v)
{
    const point_real3 x = TO_POINT_REAL3(v);
    return (point_real3)(dot(map_row(in->to_world, 0), x) + in->to_world[0].w,
                         dot(map_row(in->to_world, 1), x) + in->to_world[1].w,
                         dot(map_row(in->to_world, 2), x) + in->to_world[2].w);
}

// The solid angles at p (world) of slots first .. first + count - 1 as
// instance `in` places them, summed.
inline point_real placed_leaf_solid_angle(const Geometry* g, __global const Instance* in, point_real3 p, int first,
                                          int count)
{
    point_real sum = 0;
    for (int s = first; s < first + count; ++s) {
        __global const TriangleVerts* t = SPLIT_AT(g, tris, s);
        sum += solid_angle(p, placed_real(in, t->v0.xyz), placed_real(in, t->v1.xyz), placed_real(in, t->v2.xyz));
    }
    return sum;
}

// The scene's solid angles at p (device frame) summed, each child farther than
// beta times its world radius taken from its series; with `bounded`, *bound a
// proven bound of the sum's error.  One walk and one stack over both levels,
// as the rays' walk: a top-level leaf is an instance, walked from its mesh's
// root in its mesh's space.  `region` (point_order.cl's, winding.cl's
// signature) is not read: each point decides for itself (WINDING_BETA 6).
inline point_real winding_sum(const Geometry* g, __global const PlacedWindingNode* winding, float3 p,
                              const PointRegion* region, float beta, const bool bounded, float* bound)
{
    const point_real3 pw = TO_POINT_REAL3(p);
    point_real sum = 0;
    float err = 0.0f;
#ifdef ACCEL_BVH
    // As winding.cl's binary walk, the right child waiting while the left is
    // walked: at most one row a level of the two levels.
    int2 stack[BVH_STACK_SIZE];       // (row, its instance; -1: a top-level row)
    int sp = 0;
    int2 at = (int2)(0, -1);
    WindingSpace space = world_space(pw);
    for (;;) {
        const BvhPairNode n = *SPLIT_AT(g, nodes, at.x);
        int2 next = (int2)(-1, -1);
        for (int side = 0; side < 2; ++side) {
            const int2 child = side == 0 ? PAIR_LEFT(n) : PAIR_RIGHT(n);
            if (child.y < 0)
                continue;
            __global const PlacedWindingNode* node = winding + 2 * at.x + side;
            // (centre - q in double where the device has it: q is not rounded)
            const float3 r = convert_float3(TO_POINT_REAL3(node->centre.xyz) - space.q);
            const float3 w = times_sym(space.g, r);
            float r2 = dot(r, w);
            if (!space.similar) {
                const float3 placed = (float3)(dot(space.a0, r), dot(space.a1, r), dot(space.a2, r));
                r2 = dot(placed, placed);
            }
            const float radius2 = placed_radius2(&space, node->centre.w, node->extent);   // INFINITY: opened
            if (!space.exact && r2 > beta * beta * radius2) {
                sum += space.det * placed_far_field(node, r, w, r2, space.g);
                if (bounded)
                    err += placed_remainder_bound(node->normal.w * space.area, sqrt(radius2), r2, space.condition);
                continue;
            }
            int2 target;
            if (child.y > 0 && at.y < 0) {          // a top-level leaf: an instance, from its mesh's root
                target = (int2)(SPLIT_AT(g, instances, child.x)->root, child.x);
            } else if (child.y > 0) {   // (a similarity keeps solid angles; a mirror turns them over)
                const point_real leaf = space.similar ? leaf_solid_angle(g, space.q, child.x, child.y)
                    : placed_leaf_solid_angle(g, SPLIT_AT(g, instances, at.y), pw, child.x, child.y);
                sum += space.similar && space.det < 0.0f ? -leaf : leaf;
                continue;
            } else {
                target = (int2)(child.x, at.y);
            }
            if (next.x < 0)
                next = target;
            else
                stack[sp++] = target;
        }
        if (next.x < 0) {
            if (sp == 0)
                break;
            next = stack[--sp];
        }
        if (next.y != at.y)
            space = next.y < 0 ? world_space(pw) : instance_space(SPLIT_AT(g, instances, next.y), pw);
        at = next;
    }
#else
    for (uint i = 0; i < g->num_instances; ++i) {
        __global const Instance* in = SPLIT_AT(g, instances, i);
        sum += placed_leaf_solid_angle(g, in, pw, in->first, in->count);
    }
#endif
    if (bounded)
        *bound = err;
    return sum;
}

// ---- The PlacedWindingNodes (trace.cl's winding_nodes): a mesh's rows from its
// triangles, in its own space, as winding.cl makes WindingNodes; then the top
// level's, in the world: an instance's from its mesh's root mapped.

inline PlacedWindingNode placed_winding_node_of(float3 centre, float radius, point_real3 extent, point_real3 dipole,
                                                point_real area, const point_real* m, const point_real* t)
{
    PlacedWindingNode node;
    node.centre = (float4)(centre, radius);
    node.normal = (float4)(convert_float3(dipole), (float)area);
    node.extent = (float4)(radius_up(extent.x), radius_up(extent.y), radius_up(extent.z), 0.0f);
    for (int k = 0; k < 9; ++k)
        node.first[k] = (float)m[k];
    for (int k = 0; k < 18; ++k)
        node.second[k] = (float)t[k];
    node.pad = 0u;
    return node;
}

inline PlacedWindingNode empty_placed_winding_node(void)
{
    const point_real zeros[18] = {0};
    return placed_winding_node_of((float3)(0.0f), 0.0f, (point_real3)(0), (point_real3)(0), 0, zeros, zeros);
}

// Moments about a centre moved by -e (d = d' + e: the old centre is the new one
// plus e) -- M[i][j] += N_i e_j, T[i][jk] += M[i][j] e_k + M[i][k] e_j + N_i e_j e_k
// -- added into m and t from the moments m0, t0 and dipole n.
inline void add_moved_moments(point_real3 n3, const point_real* m0, const point_real* t0, point_real3 e3,
                              point_real* m, point_real* t)
{
    const point_real n[3] = {n3.x, n3.y, n3.z}, e[3] = {e3.x, e3.y, e3.z};
    for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j)
            m[3 * i + j] += m0[3 * i + j] + n[i] * e[j];
        for (int j = 0; j < 3; ++j)
            for (int k = j; k < 3; ++k)
                t[6 * i + SYM2_AT[j][k]] += t0[6 * i + SYM2_AT[j][k]] + m0[3 * i + j] * e[k] + m0[3 * i + k] * e[j]
                                          + n[i] * e[j] * e[k];
    }
}

// The PlacedWindingNode of the triangles in slots first .. first + count - 1
// (leaf_winding_node's sums, the moments whole).
inline PlacedWindingNode leaf_placed_winding_node(const Geometry* g, int first, int count)
{
    point_real area;
    const float3 centre = leaf_centre(g, first, count, &area);
    const point_real3 cr = TO_POINT_REAL3(centre);
    point_real3 dipole = (point_real3)(0);
    point_real m[9] = {0};
    point_real sec[18] = {0};
    point_real radius2 = 0;
    point_real3 extent = (point_real3)(0);
    for (int s = first; s < first + count; ++s) {
        __global const TriangleVerts* t = SPLIT_AT(g, tris, s);
        const point_real3 d0 = TO_POINT_REAL3(t->v0.xyz) - cr, d1 = TO_POINT_REAL3(t->v1.xyz) - cr;
        const point_real3 d2 = TO_POINT_REAL3(t->v2.xyz) - cr;
        radius2 = fmax(radius2, fmax(dot(d0, d0), fmax(dot(d1, d1), dot(d2, d2))));
        extent = fmax(extent, fmax(fabs(d0), fmax(fabs(d1), fabs(d2))));
        const point_real3 va = cross(d1 - d0, d2 - d0) / 2;
        const point_real3 sum = d0 + d1 + d2;
        dipole += va;
        const point_real v[3] = {va.x, va.y, va.z};
        const point_real x0[3] = {d0.x, d0.y, d0.z}, x1[3] = {d1.x, d1.y, d1.z}, x2[3] = {d2.x, d2.y, d2.z};
        const point_real sx[3] = {sum.x, sum.y, sum.z};
        for (int i = 0; i < 3; ++i) {
            for (int j = 0; j < 3; ++j)
                m[3 * i + j] += v[i] * sx[j] / 3;
            for (int j = 0; j < 3; ++j)
                for (int k = j; k < 3; ++k)
                    sec[6 * i + SYM2_AT[j][k]] += v[i] * (x0[j] * x0[k] + x1[j] * x1[k] + x2[j] * x2[k]
                                                          + sx[j] * sx[k]) / 12;
        }
    }
    return placed_winding_node_of(centre, radius_up(sqrt(radius2)), extent, dipole, area, m, sec);
}

// The PlacedWindingNode of a row's children joined: `a`, and `b` where
// `both` (the root row of a tree of one leaf has no right child).
inline PlacedWindingNode joined_placed_winding_node(__global const PlacedWindingNode* a,
                                                    __global const PlacedWindingNode* b, const bool both)
{
    const point_real area_a = a->normal.w, area_b = both ? b->normal.w : 0;
    const point_real3 ca = TO_POINT_REAL3(a->centre.xyz), cb = both ? TO_POINT_REAL3(b->centre.xyz) : ca;
    const point_real area = area_a + area_b;
    const float3 centre = convert_float3(area > 0 ? (area_a * ca + area_b * cb) / area : (ca + cb) / 2);
    const point_real3 cr = TO_POINT_REAL3(centre);
    point_real radius = 0;
    point_real3 extent = (point_real3)(0);
    point_real3 dipole = (point_real3)(0);
    point_real m[9] = {0};
    point_real sec[18] = {0};
    for (int c = 0; c < (both ? 2 : 1); ++c) {
        __global const PlacedWindingNode* child = c == 0 ? a : b;
        const point_real3 e = TO_POINT_REAL3(child->centre.xyz) - cr;
        radius = fmax(radius, sqrt(dot(e, e)) + child->centre.w);
        extent = fmax(extent, fabs(e) + TO_POINT_REAL3(child->extent.xyz));
        const point_real3 n = TO_POINT_REAL3(child->normal.xyz);
        dipole += n;
        point_real m0[9], t0[18];
        for (int k = 0; k < 9; ++k)
            m0[k] = child->first[k];
        for (int k = 0; k < 18; ++k)
            t0[k] = child->second[k];
        add_moved_moments(n, m0, t0, e, m, sec);
    }
    return placed_winding_node_of(centre, radius_up(radius), extent, dipole, area, m, sec);
}

// The world's PlacedWindingNode of instance `instance` (a top-level leaf):
// its mesh's root (its root row's children joined, `winding` holding them)
// mapped by to_world.  N' = cof(A) N, M' = cof(A) M A^T, T'[i] = sum_l
// cof(A)[i][l] A T[l] A^T about the mapped centre, then moved to its float32
// rounding; the radius and the area bounded through the map's scales, the
// radius INFINITY for a map conditioned worse than WINDING_PLACED_CONDITION.
inline PlacedWindingNode instance_winding_node(const Geometry* g, __global const PlacedWindingNode* winding,
                                               int instance)
{
    __global const Instance* in = SPLIT_AT(g, instances, instance);
    const BvhPairNode root = *SPLIT_AT(g, nodes, in->root);
    const PlacedWindingNode o = joined_placed_winding_node(winding + 2 * in->root, winding + 2 * in->root + 1,
                                                           PAIR_RIGHT(root).y >= 0);
    const point_real3 a0 = map_row(in->to_world, 0), a1 = map_row(in->to_world, 1), a2 = map_row(in->to_world, 2);
    const point_real a[3][3] = {{a0.x, a0.y, a0.z}, {a1.x, a1.y, a1.z}, {a2.x, a2.y, a2.z}};
    const point_real3 k0 = cross(a1, a2), k1 = cross(a2, a0), k2 = cross(a0, a1);   // cof(A)'s rows
    const point_real cof[3][3] = {{k0.x, k0.y, k0.z}, {k1.x, k1.y, k1.z}, {k2.x, k2.y, k2.z}};
    point_real m0[9], t0[18];
    // M' = cof(A) M A^T
    point_real ma[3][3];
    for (int l = 0; l < 3; ++l)
        for (int j = 0; j < 3; ++j)
            ma[l][j] = o.first[3 * l] * a[j][0] + o.first[3 * l + 1] * a[j][1] + o.first[3 * l + 2] * a[j][2];
    for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
            m0[3 * i + j] = cof[i][0] * ma[0][j] + cof[i][1] * ma[1][j] + cof[i][2] * ma[2][j];
    // T'[i] = sum_l cof(A)[i][l] A T[l] A^T
    point_real sym[3][6];
    for (int l = 0; l < 3; ++l) {
        point_real s[3][3];
        for (int j = 0; j < 3; ++j)
            for (int k = 0; k < 3; ++k)
                s[j][k] = o.second[6 * l + SYM2_AT[j][k]];
        for (int j = 0; j < 3; ++j)
            for (int k = j; k < 3; ++k) {
                point_real v = 0;
                for (int x = 0; x < 3; ++x)
                    for (int y = 0; y < 3; ++y)
                        v += a[j][x] * s[x][y] * a[k][y];
                sym[l][SYM2_AT[j][k]] = v;
            }
    }
    for (int i = 0; i < 3; ++i)
        for (int jk = 0; jk < 6; ++jk)
            t0[6 * i + jk] = cof[i][0] * sym[0][jk] + cof[i][1] * sym[1][jk] + cof[i][2] * sym[2][jk];
    const point_real3 n0 = TO_POINT_REAL3(o.normal.xyz);
    const point_real3 n = (point_real3)(dot(k0, n0), dot(k1, n0), dot(k2, n0));
    // about the mapped centre's float32 rounding
    const point_real3 exact = placed_real(in, o.centre.xyz);
    const float3 centre = convert_float3(exact);
    point_real m[9] = {0};
    point_real sec[18] = {0};
    const point_real3 moved = exact - TO_POINT_REAL3(centre);
    add_moved_moments(n, m0, t0, moved, m, sec);
    point_real g6[6], det;
    float largest, condition;
    map_scales(in, g6, &det, &largest, &condition);
    // the box of the mapped box about the mapped centre: |A| e, and the move
    const point_real3 e = TO_POINT_REAL3(o.extent.xyz);
    point_real3 extent = fabs(moved) + (point_real3)(dot(fabs(a0), e), dot(fabs(a1), e), dot(fabs(a2), e));
    point_real radius = largest * (point_real)o.centre.w + sqrt(dot(moved, moved));
    if (condition > WINDING_PLACED_CONDITION) {
        radius = INFINITY;
        extent = (point_real3)(INFINITY);
    }
    const point_real area = 1.000001 * o.normal.w * fabs(det) / in->min_scale;
    return placed_winding_node_of(centre, radius_up(radius), extent, n, area, m, sec);
}

#endif
#endif
