// Topology operations on the working triangulation (Lu & Yun §3.3 figure 4, §3.4 figure 5).
#include "core/tin.hpp"

#include <algorithm>

#include "core/error.hpp"
#include "core/predicates.hpp"
#include "core/radix_sort.hpp"

namespace tb::core {

Tin Tin::rectangle(int width, int height) {
    Tin tin;
    const std::int32_t x1 = width - 1;
    const std::int32_t y1 = height - 1;
    tin.points = {{0, 0}, {x1, 0}, {x1, y1}, {0, y1}};
    tin.vertex_edge.assign(4, kNone);
    const Index t0 = tin.add_triangle(0, 1, 2);
    const Index t1 = tin.add_triangle(0, 2, 3);
    tin.link(3 * t0 + 2, 3 * t1); // 2 -> 0 and 0 -> 2
    return tin;
}

void Tin::reserve(std::size_t vertices) {
    points.reserve(vertices);
    vertex_edge.reserve(vertices);
    triangles.reserve(6 * vertices);
    halfedges.reserve(6 * vertices);
}

Index Tin::add_point(GridPoint p) {
    points.push_back(p);
    vertex_edge.push_back(kNone);
    return static_cast<Index>(points.size() - 1);
}

Index Tin::add_triangle(Index a, Index b, Index c) {
    Index t;
    if (!free_triangles.empty()) {
        t = free_triangles.back();
        free_triangles.pop_back();
    } else {
        t = static_cast<Index>(triangle_slots());
        triangles.resize(triangles.size() + 3);
        halfedges.resize(halfedges.size() + 3);
    }
    fill_triangle(t, a, b, c);
    return t;
}

void Tin::fill_triangle(Index t, Index a, Index b, Index c) {
    triangles[3 * t] = a;
    triangles[3 * t + 1] = b;
    triangles[3 * t + 2] = c;
    halfedges[3 * t] = halfedges[3 * t + 1] = halfedges[3 * t + 2] = kNone;
    TB_ASSERT(orient2d(points[a], points[b], points[c]) > 0);
    touch(t);
}

void Tin::free_triangle(Index t) {
    clear_triangle(t);
    free_triangles.push_back(t);
}

void Tin::clear_triangle(Index t) {
    for (Index e = 3 * t; e < 3 * t + 3; ++e) {
        triangles[e] = kNone;
        halfedges[e] = kNone;
    }
}

void Tin::split_triangle(Index t, Index p, std::array<Index, 4>& out) {
    const Index a = triangles[3 * t], b = triangles[3 * t + 1], c = triangles[3 * t + 2];
    const Index ab = halfedges[3 * t], bc = halfedges[3 * t + 1], ca = halfedges[3 * t + 2];
    // t -> (a, b, p); t1 = (b, c, p); t2 = (c, a, p)
    triangles[3 * t + 2] = p;
    TB_ASSERT(orient2d(points[a], points[b], points[p]) > 0);
    const Index t1 = add_triangle(b, c, p);
    const Index t2 = add_triangle(c, a, p);
    link(3 * t, ab);
    link(3 * t1, bc);
    link(3 * t2, ca);
    link(3 * t + 1, 3 * t1 + 2);  // b -> p | p -> b
    link(3 * t1 + 1, 3 * t2 + 2); // c -> p | p -> c
    link(3 * t2 + 1, 3 * t + 2);  // a -> p | p -> a
    touch(t);
    out = {t, t1, t2, kNone};
}

int Tin::split_edge(Index e, Index p, std::array<Index, 4>& out) {
    //        c                 c
    //      /   \             / | \      .
    //     a --e-> b   ->    a--p--b
    //      \ <-f /           \ | /
    //        d                 d
    const Index f = halfedges[e];
    const Index t = e / 3;
    const Index a = triangles[e], b = triangles[next_edge(e)], c = triangles[prev_edge(e)];
    const Index bc = halfedges[next_edge(e)], ca = halfedges[prev_edge(e)];
    // t -> (a, p, c); t1 = (p, b, c)
    triangles[3 * t] = a;
    triangles[3 * t + 1] = p;
    triangles[3 * t + 2] = c;
    TB_ASSERT(orient2d(points[a], points[p], points[c]) > 0);
    const Index t1 = add_triangle(p, b, c);
    link(3 * t + 2, ca);
    link(3 * t1 + 1, bc);
    link(3 * t + 1, 3 * t1 + 2); // p -> c | c -> p
    touch(t);
    if (f == kNone) {
        halfedges[3 * t] = kNone;
        halfedges[3 * t1] = kNone;
        out = {t, t1, kNone, kNone};
        return 2;
    }
    const Index u = f / 3;
    const Index d = triangles[prev_edge(f)];
    const Index ad = halfedges[next_edge(f)], db = halfedges[prev_edge(f)];
    // u -> (b, p, d); u1 = (p, a, d)
    triangles[3 * u] = b;
    triangles[3 * u + 1] = p;
    triangles[3 * u + 2] = d;
    TB_ASSERT(orient2d(points[b], points[p], points[d]) > 0);
    const Index u1 = add_triangle(p, a, d);
    link(3 * u + 2, db);
    link(3 * u1 + 1, ad);
    link(3 * u + 1, 3 * u1 + 2); // p -> d | d -> p
    link(3 * t, 3 * u1);         // a -> p | p -> a
    link(3 * t1, 3 * u);         // p -> b | b -> p
    touch(u);
    out = {t, t1, u, u1};
    return 4;
}

Index Tin::flip(Index e) {
    //        r                 r
    //      /   \             / | \      .
    //     p --e-> q   ->    p  |  q
    //      \ <-f /           \ | /
    //        s                 s
    const Index f = halfedges[e];
    TB_ASSERT(f != kNone);
    const Index t = e / 3, u = f / 3;
    const Index p = triangles[e], q = triangles[next_edge(e)], r = triangles[prev_edge(e)];
    const Index s = triangles[prev_edge(f)];
    const Index qr = halfedges[next_edge(e)], rp = halfedges[prev_edge(e)];
    const Index ps = halfedges[next_edge(f)], sq = halfedges[prev_edge(f)];
    TB_ASSERT(orient2d(points[r], points[p], points[s]) > 0);
    TB_ASSERT(orient2d(points[s], points[q], points[r]) > 0);
    // t -> (r, p, s), u -> (s, q, r)
    triangles[3 * t] = r;
    triangles[3 * t + 1] = p;
    triangles[3 * t + 2] = s;
    triangles[3 * u] = s;
    triangles[3 * u + 1] = q;
    triangles[3 * u + 2] = r;
    link(3 * t, rp);
    link(3 * t + 1, ps);
    link(3 * u, sq);
    link(3 * u + 1, qr);
    link(3 * t + 2, 3 * u + 2); // s -> r | r -> s
    touch(t);
    touch(u);
    return 3 * t + 2;
}

void Tin::ring(Index v, std::vector<Index>& out) const {
    out.clear();
    const Index e0 = vertex_edge[v];
    TB_ASSERT(e0 != kNone);
    // Counter-clockwise from e0; an interior vertex comes back to e0.
    Index e = e0;
    do {
        out.push_back(e);
        e = halfedges[prev_edge(e)];
    } while (e != kNone && e != e0);
    if (e == e0) {
        return;
    }
    // A border vertex: restart from the border edge leaving v (rotate clockwise to it).
    Index first = e0;
    while (halfedges[first] != kNone) {
        first = next_edge(halfedges[first]);
    }
    out.clear();
    for (e = first; e != kNone; e = halfedges[prev_edge(e)]) {
        out.push_back(e);
    }
}

bool Tin::on_border(Index v) const {
    std::vector<Index> r;
    ring(v, r);
    return halfedges[r.front()] == kNone;
}

namespace {

// Bit i of the low 21 bits of v moved to bit 2 * i (the classic shift-and-mask spread).
std::uint64_t spread_bits(std::uint64_t v) {
    v &= 0x1FFFFFu;
    v = (v | (v << 16)) & 0x0000FFFF0000FFFFu;
    v = (v | (v << 8)) & 0x00FF00FF00FF00FFu;
    v = (v | (v << 4)) & 0x0F0F0F0F0F0F0F0Fu;
    v = (v | (v << 2)) & 0x3333333333333333u;
    v = (v | (v << 1)) & 0x5555555555555555u;
    return v;
}

} // namespace

// x's bits at even positions, y's at odd ones (coordinates are below 2^21).
std::uint64_t z_order_key(GridPoint p) {
    return spread_bits(static_cast<std::uint32_t>(p.x)) |
           (spread_bits(static_cast<std::uint32_t>(p.y)) << 1);
}

namespace {

// Moves the record in every slot i to slot to[i] (`to` a permutation of its indices) by swaps
// along the permutation's cycles, each of which puts one record in its final slot. No second
// array: on this path the arrays are the mesher's largest, and fresh memory is what a copy
// would cost most. `to` is left as the identity.
template <typename Swap> void permute_in_place(LargeVector<Index>& to, const Swap& swap_records) {
    for (Index i = 0; i < to.size(); ++i) {
        while (to[i] != i) {
            const Index j = to[i];
            swap_records(i, j);
            std::swap(to[i], to[j]);
        }
    }
}

} // namespace

void Tin::compact(const std::function<void(Index, Index)>& swap_also) {
    // Vertices by the Z-order of their position (unique, so the order is total).
    LargeVector<std::pair<std::uint64_t, Index>> keys;
    keys.reserve(points.size());
    for (Index v = 0; v < points.size(); ++v) {
        if (vertex_edge[v] != kNone) {
            keys.push_back({z_order_key(points[v]), v});
        }
    }
    radix_sort(keys, [](const std::pair<std::uint64_t, Index>& k) { return k.first; });
    // New vertex numbers: the live ones in that order, then the removed ones (dropped below).
    LargeVector<Index> vmap(points.size(), kNone);
    for (Index i = 0; i < keys.size(); ++i) {
        vmap[keys[i].second] = i;
    }
    const auto live_vertices = static_cast<Index>(keys.size());
    Index next = live_vertices;
    for (Index& v : vmap) {
        v = v == kNone ? next++ : v;
    }
    // Triangles by their lowest new vertex (a counting sort; ties keep slot order), then the
    // freed slots.
    const auto lowest = [&](Index t) {
        return std::min(
            {vmap[triangles[3 * t]], vmap[triangles[3 * t + 1]], vmap[triangles[3 * t + 2]]});
    };
    LargeVector<Index> first(points.size() + 1, 0);
    for (Index t = 0; t < triangle_slots(); ++t) {
        if (alive(t)) {
            ++first[lowest(t) + 1];
        }
    }
    for (std::size_t v = 1; v < first.size(); ++v) {
        first[v] += first[v - 1];
    }
    const Index live_triangles = first.back();
    LargeVector<Index> tmap(triangle_slots(), kNone);
    next = live_triangles;
    for (Index t = 0; t < triangle_slots(); ++t) {
        tmap[t] = alive(t) ? first[lowest(t)]++ : next++;
    }
    // Renumber the references first, then move the records.
    for (Index t = 0; t < triangle_slots(); ++t) {
        if (!alive(t)) {
            continue;
        }
        for (Index e = 3 * t; e < 3 * t + 3; ++e) {
            TB_ASSERT(vertex_edge[triangles[e]] != kNone); // a live triangle's vertices are live
            triangles[e] = vmap[triangles[e]];
            const Index twin = halfedges[e];
            halfedges[e] = twin == kNone ? kNone : 3 * tmap[twin / 3] + twin % 3;
        }
    }
    permute_in_place(tmap, [&](Index a, Index b) {
        for (Index k = 0; k < 3; ++k) {
            std::swap(triangles[3 * a + k], triangles[3 * b + k]);
            std::swap(halfedges[3 * a + k], halfedges[3 * b + k]);
        }
        if (swap_also) {
            swap_also(a, b);
        }
    });
    permute_in_place(vmap, [&](Index a, Index b) { std::swap(points[a], points[b]); });
    // Shrinking keeps the capacity: room reserved for growth stays.
    points.resize(live_vertices);
    triangles.resize(3 * std::size_t{live_triangles});
    halfedges.resize(3 * std::size_t{live_triangles});
    free_triangles.clear();
    vertex_edge.assign(points.size(), kNone);
    for (Index e = 0; e < triangles.size(); ++e) {
        if (vertex_edge[triangles[e]] == kNone) {
            vertex_edge[triangles[e]] = e;
        }
    }
}

Mesh Tin::to_mesh(const std::vector<float>& heights, int width) const {
    Mesh mesh;
    LargeVector<Index> vmap(points.size(), kNone);
    LargeVector<Index> tmap(triangle_slots(), kNone);
    Index nt = 0;
    for (Index t = 0; t < triangle_slots(); ++t) {
        if (alive(t)) {
            tmap[t] = nt++;
        }
    }
    mesh.points.reserve(points.size());
    mesh.z.reserve(points.size());
    mesh.triangles.resize(3 * std::size_t{nt});
    mesh.halfedges.resize(3 * std::size_t{nt});
    for (Index t = 0; t < triangle_slots(); ++t) {
        if (!alive(t)) {
            continue;
        }
        for (Index k = 0; k < 3; ++k) {
            const Index e = 3 * t + k;
            const Index v = triangles[e];
            if (vmap[v] == kNone) {
                vmap[v] = static_cast<Index>(mesh.points.size());
                mesh.points.push_back(points[v]);
                mesh.z.push_back(
                    heights[static_cast<std::size_t>(points[v].y) * width + points[v].x]);
            }
            const Index out = 3 * tmap[t] + k;
            mesh.triangles[out] = vmap[v];
            const Index twin = halfedges[e];
            mesh.halfedges[out] = twin == kNone ? kNone : 3 * tmap[twin / 3] + twin % 3;
        }
    }
    return mesh;
}

} // namespace tb::core
