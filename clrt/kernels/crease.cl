// The crease split of clrt.scene.mesh.Mesh.split_at_creases and the smooth
// vertex normals of Mesh.vertex_normals, made on the device from the uploaded
// vertices and faces (driven by clrt/device/crease.py, which lists the order):
//   weld_insert, weld_read   each vertex's smallest-index twin at the same
//                            position, bitwise (a hash table, atomic_min)
//   area_normals             each face's cross product, in float64
//   edge_ends                each half-edge's welded ends
//   edge_insert              each half-edge into a hash table by its two welded
//                            ends; the half-edges of one edge in a list
//   edge_joins               each half-edge paired with the next one (by index)
//                            of its edge; a smooth pair joins two corner pairs
//   hook_joins, compress_labels   union-find over the joins
//   scan_tiles, scan_tile_sums, scan_apply   exclusive prefix sums (the roots'
//                            new numbers; the vertices' corner lists)
//   split_vertices           each corner's new vertex, each vertex's source
//   count_corners, place_corners, vertex_normals   each vertex's corners
//                            listed, put in the host's order, summed
//   triangle_info            the TriangleInfo of every slot (the BVH's order)
// Every answer is the host's bit for bit: the groups of corners do not depend
// on the order of the joins (each group ends labelled by its smallest corner,
// as the host's), an edge's half-edges pair by index as the host's stable
// sort pairs them, and the float64 sums add the same terms in the same order
// without contraction.  Work-groups of BUILD_GROUP items (the builder's size).
#ifndef CLRT_CREASE_CL
#define CLRT_CREASE_CL

#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#pragma OPENCL FP_CONTRACT OFF

#include "build_scan.cl"

#define EMPTY (-1)
#define NO_CORNER 0x7fffffff

// Segments of corners no longer than this are sorted in private memory.
#define SHORT_LIST 32

// MurmurHash3's finaliser: every input bit reaches every output bit.
inline uint mix32(uint h)
{
    h ^= h >> 16;
    h *= 0x85ebca6bu;
    h ^= h >> 13;
    h *= 0xc2b2ae35u;
    h ^= h >> 16;
    return h;
}

// x rounded to a double where it stands: a product passed through here
// is never fused with the sum it enters into one FMA, which would round
// once where the host rounds twice.  FP_CONTRACT OFF asks the same of the
// compiler; this makes sure of it whatever a compiler does with the pragma
// (NVIDIA's fuses float products regardless: triangle.cl).
inline double rounded(const double x)
{
    volatile double kept = x;
    return kept;
}

// Half-edge h = 3f + k runs from corner k of face f to corner k + 1 (mod 3).
inline uint next_corner(uint h)
{
    const uint f = h / 3u;
    return h - 3u * f == 2u ? 3u * f : h + 1u;
}

// ---------------------------------------------------------------- the weld
//
// table[s]: a vertex at the slot's position (EMPTY: none), lowered by
// atomic_min to the smallest of those at that position; linear probing.
// Every vertex ever held by a slot has the slot's position, so a slot's value
// may be compared while it changes.  slot_of[v]: the slot of v's position.
__kernel __attribute__((reqd_work_group_size(BUILD_GROUP, 1, 1)))
void weld_insert(const global uint* vertex_bits, const uint num_vertices, volatile global int* table,
                 const uint mask, global uint* slot_of)
{
    const uint v = get_global_id(0);
    if (v >= num_vertices)
        return;
    const uint3 p = vload3(v, vertex_bits);
    uint s = mix32(mix32(mix32(p.x) ^ p.y) ^ p.z) & mask;
    for (;;) {
        int held = table[s];
        if (held == EMPTY) {
            held = atomic_cmpxchg(&table[s], EMPTY, (int)v);
            if (held == EMPTY)
                break;                        // the first vertex seen at this position
        }
        if (all(vload3(held, vertex_bits) == p)) {
            atomic_min(&table[s], (int)v);
            break;
        }
        s = (s + 1u) & mask;
    }
    slot_of[v] = s;
}

// weld[v]: the smallest vertex at v's position (Mesh._split's weld has the
// same classes, numbered otherwise: only the classes matter).
__kernel __attribute__((reqd_work_group_size(BUILD_GROUP, 1, 1)))
void weld_read(const global int* table, const global uint* slot_of, const uint num_vertices, global int* weld)
{
    const uint v = get_global_id(0);
    if (v < num_vertices)
        weld[v] = table[slot_of[v]];
}

// ------------------------------------------------------------ face normals
//
// Mesh._area_normals: (p1 - p0) x (p2 - p0), the corners widened to float64
// first, each product rounded before the difference.
__kernel __attribute__((reqd_work_group_size(BUILD_GROUP, 1, 1)))
void area_normals(const global float* vertices, const global int* faces, const uint num_faces, global double* area)
{
    const uint f = get_global_id(0);
    if (f >= num_faces)
        return;
    const double3 p0 = convert_double3(vload3(faces[3 * f], vertices));
    const double3 e1 = convert_double3(vload3(faces[3 * f + 1], vertices)) - p0;
    const double3 e2 = convert_double3(vload3(faces[3 * f + 2], vertices)) - p0;
    vstore3((double3)(rounded(e1.y * e2.z) - rounded(e1.z * e2.y), rounded(e1.z * e2.x) - rounded(e1.x * e2.z),
                      rounded(e1.x * e2.y) - rounded(e1.y * e2.x)), f, area);
}

// (a.x b.x + a.y b.y) + a.z b.z, each product rounded first.
inline double dot_rounded(const double3 a, const double3 b)
{
    return (rounded(a.x * b.x) + rounded(a.y * b.y)) + rounded(a.z * b.z);
}

// n over its length sqrt((x x + y y) + z z) (clrt.scene.mesh.unit_rows),
// zero where the length is 0.
inline double3 unit(const double3 n)
{
    const double length = sqrt(dot_rounded(n, n));
    return length > 0.0 ? n / length : (double3)(0.0);
}

// ------------------------------------------------------------------ edges
//
// ends[h]: half-edge h's welded start and end, so that a probe compares
// another half-edge's edge in one load.
__kernel __attribute__((reqd_work_group_size(BUILD_GROUP, 1, 1)))
void edge_ends(const global int* faces, const global int* weld, const uint num_corners, global int* ends)
{
    const uint h = get_global_id(0);
    if (h < num_corners)
        vstore2((int2)(weld[faces[h]], weld[faces[next_corner(h)]]), h, ends);
}

// An edge: its two welded ends, the smaller first.
inline int2 edge_of(const global int* ends, uint h)
{
    const int2 e = vload2(h, ends);
    return (int2)(min(e.x, e.y), max(e.x, e.y));
}

// table[s]: the last half-edge entered of the slot's edge (EMPTY: none);
// next[h]: the one entered before h (EMPTY: h was the first), so that the
// slot heads a list of its edge's half-edges, in no particular order.
__kernel __attribute__((reqd_work_group_size(BUILD_GROUP, 1, 1)))
void edge_insert(const global int* ends, const uint num_corners, volatile global int* table, const uint mask,
                 global uint* slot_of, global int* next)
{
    const uint h = get_global_id(0);
    if (h >= num_corners)
        return;
    const int2 key = edge_of(ends, h);
    uint s = mix32(mix32((uint)key.x) ^ (uint)key.y) & mask;
    for (;;) {
        int held = table[s];
        if (held == EMPTY) {
            held = atomic_cmpxchg(&table[s], EMPTY, (int)h);
            if (held == EMPTY) {
                next[h] = EMPTY;
                break;
            }
        }
        if (all(edge_of(ends, (uint)held) == key)) {
            next[h] = atomic_xchg(&table[s], (int)h);
            break;
        }
        s = (s + 1u) & mask;
    }
    slot_of[h] = s;
}

// Half-edge h1 and the next half-edge h2 of its edge (by index), as the
// host's stable sort pairs them: where their faces differ and meet at no
// more than the crease angle (the cosine of Mesh.face_normals', summed x,
// y, z), the corners at each end of the edge are
// joined -- h1's start with h2's start if both run the same way, else with
// h2's end.  joins[2 h1], joins[2 h1 + 1]: the two joins, (-1, -1) where
// there are none.  Also label[h1] = h1: every corner starts as its own root.
__kernel __attribute__((reqd_work_group_size(BUILD_GROUP, 1, 1)))
void edge_joins(const global int* ends, const global double* area, const uint num_corners, const global int* table,
                const global uint* slot_of, const global int* next, const double cos_limit, global int* joins,
                global int* label)
{
    const uint h1 = get_global_id(0);
    if (h1 >= num_corners)
        return;
    label[h1] = (int)h1;
    int h2 = NO_CORNER;
    for (int x = table[slot_of[h1]]; x != EMPTY; x = next[x])
        if (x > (int)h1 && x < h2)
            h2 = x;
    int4 pair = (int4)(-1);
    if (h2 != NO_CORNER) {
        const uint f1 = h1 / 3u, f2 = (uint)h2 / 3u;
        if (f1 != f2 && dot_rounded(unit(vload3(f1, area)), unit(vload3(f2, area))) >= cos_limit) {
            const int e1 = (int)next_corner(h1), e2 = (int)next_corner((uint)h2);
            const bool straight = ends[2 * h1] == ends[2 * h2];        // the same welded start
            pair = (int4)((int)h1, straight ? h2 : e2, e1, straight ? e2 : h2);
        }
    }
    vstore4(pair, h1, joins);
}

// -------------------------------------------------------------- union-find
//
// label[c] <= c, and a corner with label[c] == c is a root.  Labels only
// decrease, each to a corner of the same group, so a walk up them ends.
inline int find_root(volatile global int* label, int c)
{
    int up = label[c];
    while (up != c) {
        c = up;
        up = label[c];
    }
    return c;
}

// Each join whose corners have different roots hooks the larger root under
// the smaller (atomic_min: a root hooked twice keeps the smaller; a join
// that loses so is still apart, and taken again in the next round), and
// says so in *changed.  Once a round changes nothing, every join lies within
// one tree, rooted at its smallest corner (no corner below a group's least
// can ever be written to it): the host's labels.
__kernel __attribute__((reqd_work_group_size(BUILD_GROUP, 1, 1)))
void hook_joins(const global int* joins, const uint num_joins, volatile global int* label, global int* changed)
{
    const uint j = get_global_id(0);
    if (j >= num_joins)
        return;
    const int2 join = vload2(j, joins);
    if (join.x < 0)
        return;
    const int a = find_root(label, join.x), b = find_root(label, join.y);
    if (a != b) {
        atomic_min(&label[max(a, b)], min(a, b));
        *changed = 1;
    }
}

// Every corner labelled by its root, and is_root[c] = 1 for the roots.
__kernel __attribute__((reqd_work_group_size(BUILD_GROUP, 1, 1)))
void compress_labels(volatile global int* label, const uint num_corners, global uint* is_root)
{
    const uint c = get_global_id(0);
    if (c >= num_corners)
        return;
    const int root = find_root(label, (int)c);
    label[c] = root;
    is_root[c] = root == (int)c;
}

// ------------------------------------------------------------ prefix sums
//
// An exclusive prefix sum of data[0, n) in place, in three launches: each
// work-group's tile of SCAN_TILE entries summed, the tiles' sums scanned by
// one work-group (their total after them, at tile_sums[tiles]), each tile
// scanned from its tile's start.
#define SCAN_TILE (BUILD_GROUP * SCAN_ITEMS)

// The sum of a work-item's SCAN_ITEMS values from `first` (those below n).
inline uint items_sum(const global uint* data, uint n, uint first)
{
    uint sum = 0;
    for (uint k = 0; k < SCAN_ITEMS; ++k)
        if (first + k < n)
            sum += data[first + k];
    return sum;
}

__kernel __attribute__((reqd_work_group_size(BUILD_GROUP, 1, 1)))
void scan_tiles(const global uint* data, const uint n, global uint* tile_sums)
{
    local uint scratch[BUILD_GROUP];
    const uint first = get_group_id(0) * SCAN_TILE + get_local_id(0) * SCAN_ITEMS;
    const uint sum = items_sum(data, n, first);
    uint total;
    group_exclusive_scan(sum, scratch, &total);
    if (get_local_id(0) == 0)
        tile_sums[get_group_id(0)] = total;
}

__kernel __attribute__((reqd_work_group_size(BUILD_GROUP, 1, 1)))
void scan_tile_sums(global uint* tile_sums, const uint tiles)
{
    local uint scratch[BUILD_GROUP];
    const uint total = scan_in_one_group(tile_sums, tiles, scratch);
    if (get_local_id(0) == 0)
        tile_sums[tiles] = total;
}

__kernel __attribute__((reqd_work_group_size(BUILD_GROUP, 1, 1)))
void scan_apply(global uint* data, const uint n, const global uint* tile_sums)
{
    local uint scratch[BUILD_GROUP];
    const uint first = get_group_id(0) * SCAN_TILE + get_local_id(0) * SCAN_ITEMS;
    const uint sum = items_sum(data, n, first);
    uint total;
    uint prefix = tile_sums[get_group_id(0)] + group_exclusive_scan(sum, scratch, &total);
    for (uint k = 0; k < SCAN_ITEMS; ++k)
        if (first + k < n) {
            const uint value = data[first + k];
            data[first + k] = prefix;
            prefix += value;
        }
}

// ------------------------------------------------------------ the split
//
// The roots, numbered in corner order (index: the exclusive sum of
// is_root), are the new vertices: corner_vertex[c] is c's root's number (the
// split faces, (F, 3) in corner order) and source[v] the input vertex at
// vertex v's root (its position: the split's vertices).
__kernel __attribute__((reqd_work_group_size(BUILD_GROUP, 1, 1)))
void split_vertices(const global int* label, const global uint* index, const global int* faces,
                    const uint num_corners, global int* corner_vertex, global int* source)
{
    const uint c = get_global_id(0);
    if (c >= num_corners)
        return;
    const int root = label[c];
    corner_vertex[c] = (int)index[root];
    if (root == (int)c)
        source[index[c]] = faces[c];
}

// ---------------------------------------------------------- vertex normals
//
// Each vertex's corners listed together: counts[v] corners (count_corners),
// whose exclusive sum gives each list's start; place_corners then moves each
// start to the list's end as it fills it (atomic_inc), so that afterwards
// vertex v's list runs from ends[v - 1] (0 for v = 0) to ends[v], in no
// particular order.
__kernel __attribute__((reqd_work_group_size(BUILD_GROUP, 1, 1)))
void count_corners(const global int* corner_vertex, const uint num_corners, volatile global uint* counts)
{
    const uint c = get_global_id(0);
    if (c < num_corners)
        atomic_inc(&counts[corner_vertex[c]]);
}

__kernel __attribute__((reqd_work_group_size(BUILD_GROUP, 1, 1)))
void place_corners(const global int* corner_vertex, const uint num_corners, volatile global uint* ends,
                   global uint* corner_list)
{
    const uint c = get_global_id(0);
    if (c < num_corners)
        corner_list[atomic_inc(&ends[corner_vertex[c]])] = c;
}

// Where corner c = 3f + k comes in Mesh.vertex_normals' sums: every face's
// corner 0 first, then every corner 1, then every corner 2.
inline uint sum_rank(uint c, uint num_faces)
{
    const uint f = c / 3u;
    return (c - 3u * f) * num_faces + f;
}

// Heapsort of list[0, n) by sum_rank, in place: a long list (a vertex that
// many faces share) in O(n log n) steps of one work-item.
inline void sift_down(global uint* list, uint root, const uint n, const uint num_faces)
{
    const uint item = list[root];
    const uint rank = sum_rank(item, num_faces);
    for (;;) {
        uint child = 2u * root + 1u;
        if (child >= n)
            break;
        if (child + 1u < n && sum_rank(list[child + 1u], num_faces) > sum_rank(list[child], num_faces))
            ++child;
        if (sum_rank(list[child], num_faces) <= rank)
            break;
        list[root] = list[child];
        root = child;
    }
    list[root] = item;
}

inline void heap_sort(global uint* list, const uint n, const uint num_faces)
{
    for (uint i = n / 2u; i-- > 0u;)
        sift_down(list, i, n, num_faces);
    for (uint end = n; end-- > 1u;) {
        const uint top = list[0];
        list[0] = list[end];
        list[end] = top;
        sift_down(list, 0u, end, num_faces);
    }
}

// Mesh.vertex_normals for vertex v: the area normals of the faces at its
// corners summed from 0.0 in the host's order (sum_rank), each component on
// its own, then over their length (unit), rounded to float32 (w 0).
__kernel __attribute__((reqd_work_group_size(BUILD_GROUP, 1, 1)))
void vertex_normals(global uint* corner_list, const global uint* ends, const uint num_vertices, const uint num_faces,
                    const global double* area, global float* normals)
{
    const uint v = get_global_id(0);
    if (v >= num_vertices)
        return;
    const uint start = v > 0u ? ends[v - 1u] : 0u, n = ends[v] - start;
    global uint* list = corner_list + start;
    double3 sum = (double3)(0.0);
    if (n <= SHORT_LIST) {                     // insertion sort in private memory
        uint rank[SHORT_LIST];
        for (uint i = 0; i < n; ++i) {
            const uint r = sum_rank(list[i], num_faces);
            uint j = i;
            for (; j > 0u && rank[j - 1u] > r; --j)
                rank[j] = rank[j - 1u];
            rank[j] = r;
        }
        for (uint i = 0; i < n; ++i)
            sum += vload3(rank[i] % num_faces, area);
    } else {
        heap_sort(list, n, num_faces);
        for (uint i = 0; i < n; ++i)
            sum += vload3(list[i] / 3u, area);
    }
    vstore4((float4)(convert_float3(unit(sum)), 0.0f), v, normals);
}

// --------------------------------------------------------- triangle info
//
// tri_info[slot] (TriangleInfo, as ints): the split vertices of the slot's
// triangle prim_ids[slot] and its material -- material_base, or where
// per_face is set, material_base + 1 + face_material[triangle] (as
// clrt.scene.arrays.flatten_scene numbers them).
__kernel __attribute__((reqd_work_group_size(BUILD_GROUP, 1, 1)))
void triangle_info(const global int* corner_vertex, const global int* prim_ids, const uint num_faces,
                   const global int* face_material, const int per_face, const int material_base,
                   global int* tri_info)
{
    const uint slot = get_global_id(0);
    if (slot >= num_faces)
        return;
    const int f = prim_ids[slot];
    const int material = per_face ? material_base + 1 + face_material[f] : material_base;
    vstore4((int4)(vload3(f, corner_vertex), material), slot, tri_info);
}

#endif
