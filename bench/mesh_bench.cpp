// Mesher benchmark (not a test): meshes fixed heightmaps at a list of eps and prints one TSV
// line per case and effort level:
//   input size eps ms triangles achieved_max_err peer_triangles ratio effort
// (the peer columns are "-" here; bench/mesh_bench.sh fills them from delatin's run).
// Exits 1 if any achieved_max_err > eps: the bound is the product, speed is secondary.
//
// usage: mesh_bench [--reps N] [--effort fast|balanced|best|all] [--json DIR] [--phases]
//                   [--threads 1|2] [--no-check] INPUT EPS[,EPS...] [INPUT EPS... ...]
//   INPUT = NAME=FILE.f32:W:H  raw little-endian float32, row-major (shared/bench format)
//         | synth:SEED:W:H     seeded synthetic terrain (ridges + noise, 0.1 height steps)
// --effort picks core's TriangulateOptions::effort (default best, core's default); `all` runs
// the three levels, alternated in every rep so that they see the same load, and prints a line
// for each (fast, balanced, best).
// --threads sets TriangulateOptions::threads (default 2, core's default; the mesh is the same
// for 1).
// --no-check times triangulate without its final exact error pass (TriangulateOptions::
// check_error off, as the tiler runs it). Every mesh is still measured by max_error after the
// timing, and the script still runs linf_check on it.
// --json DIR writes every mesh as DIR/NAME-epsE-LEVEL.json for shared/bench's linf_check.
// --phases prints instead, per case, where the fastest run's time went (core's
// TriangulatePhases; phases_ms is their sum):  input size eps phases_ms triangles anchors_ms
// start_ms first_scan_ms split_ms resplit_ms renumber_ms merge_ms finish_ms anchors
// split_triangles merge_passes removed effort   (not with --json)
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include "core/triangulate.hpp"

namespace {

using tb::core::HeightGrid;

// Synthetic terrain: a few octaves of smoothed value noise plus a ridge, quantized to 0.1 like
// a DEM. Deterministic for a seed (its own LCG, no <random> distribution differences).
HeightGrid synth(std::uint64_t seed, int w, int h) {
    HeightGrid g;
    g.width = w;
    g.height = h;
    g.heights.assign(static_cast<std::size_t>(w) * h, 0.0f);
    std::uint64_t state = seed * 6364136223846793005ULL + 1442695040888963407ULL;
    auto rnd = [&state]() {
        state = state * 6364136223846793005ULL + 1442695040888963407ULL;
        return static_cast<double>(state >> 11) / 9007199254740992.0;
    };
    double amp = 400.0;
    for (int cell = 256; cell >= 4; cell /= 2, amp *= 0.5) {
        const int gw = w / cell + 2, gh = h / cell + 2;
        std::vector<double> lat(static_cast<std::size_t>(gw) * gh);
        for (auto& v : lat) {
            v = (rnd() - 0.5) * amp;
        }
        for (int y = 0; y < h; ++y) {
            for (int x = 0; x < w; ++x) {
                const double fx = static_cast<double>(x) / cell, fy = static_cast<double>(y) / cell;
                const int ix = static_cast<int>(fx), iy = static_cast<int>(fy);
                double tx = fx - ix, ty = fy - iy;
                tx = tx * tx * (3 - 2 * tx);
                ty = ty * ty * (3 - 2 * ty);
                auto L = [&](int i, int j) { return lat[static_cast<std::size_t>(j) * gw + i]; };
                const double v = (L(ix, iy) * (1 - tx) + L(ix + 1, iy) * tx) * (1 - ty) +
                                 (L(ix, iy + 1) * (1 - tx) + L(ix + 1, iy + 1) * tx) * ty;
                g.heights[static_cast<std::size_t>(y) * w + x] += static_cast<float>(v);
            }
        }
    }
    for (int y = 0; y < h; ++y) {
        for (int x = 0; x < w; ++x) {
            float& z = g.heights[static_cast<std::size_t>(y) * w + x];
            const double ridge = 300.0 - 2.0 * std::abs(x - 0.6 * y - 0.2 * w);
            z = static_cast<float>(std::round((z + std::max(0.0, ridge)) * 10.0) / 10.0);
        }
    }
    return g;
}

bool load(const std::string& spec, std::string& name, HeightGrid& g) {
    std::vector<std::string> parts;
    std::stringstream ss(spec);
    for (std::string p; std::getline(ss, p, ':');) {
        parts.push_back(p);
    }
    if (parts.size() == 4 && parts[0] == "synth") {
        g = synth(std::stoull(parts[1]), std::stoi(parts[2]), std::stoi(parts[3]));
        name = "synth";
        name.append(parts[1]).append("-").append(parts[2]);
        return true;
    }
    const auto eq = spec.find('=');
    if (parts.size() != 3 || eq == std::string::npos) {
        return false;
    }
    name = spec.substr(0, eq);
    const std::string file = parts[0].substr(eq + 1);
    g.width = std::stoi(parts[1]);
    g.height = std::stoi(parts[2]);
    g.heights.resize(static_cast<std::size_t>(g.width) * g.height);
    std::ifstream in(file, std::ios::binary);
    in.read(reinterpret_cast<char*>(g.heights.data()),
            static_cast<std::streamsize>(g.heights.size() * sizeof(float)));
    if (!in) {
        std::cerr << "mesh_bench: " << file << ": cannot read " << g.heights.size()
                  << " float32 samples\n";
        std::exit(2);
    }
    return true;
}

void write_json(const std::string& path, const tb::core::Mesh& m) {
    std::ofstream out(path);
    out.precision(17); // the float heights exactly, so the checker sees the grid's z
    out << "{\"vertices\":[";
    for (std::size_t v = 0; v < m.points.size(); ++v) {
        out << (v ? "," : "") << m.points[v].x << ',' << m.points[v].y << ','
            << static_cast<double>(m.z[v]);
    }
    out << "],\"triangles\":[";
    for (std::size_t e = 0; e < m.triangles.size(); ++e) {
        out << (e ? "," : "") << m.triangles[e];
    }
    out << "]}\n";
}

} // namespace

int main(int argc, char** argv) {
    int reps = 3;
    int threads = 2;
    bool phases = false;
    bool check_error = true;
    std::vector<tb::core::Effort> levels{tb::core::Effort::Best};
    std::string json_dir;
    std::vector<std::string> args(argv + 1, argv + argc);
    for (std::size_t i = 0; i < args.size();) {
        if (args[i] == "--reps" && i + 1 < args.size()) {
            reps = std::max(1, std::stoi(args[i + 1]));
            args.erase(args.begin() + static_cast<std::ptrdiff_t>(i),
                       args.begin() + static_cast<std::ptrdiff_t>(i) + 2);
        } else if (args[i] == "--effort" && i + 1 < args.size()) {
            if (args[i + 1] == "all") {
                levels = {
                    tb::core::Effort::Fast, tb::core::Effort::Balanced, tb::core::Effort::Best};
            } else {
                try {
                    levels = {tb::core::parse_effort(args[i + 1])};
                } catch (const std::exception& e) {
                    std::cerr << "mesh_bench: --effort: " << e.what() << " (or all)\n";
                    return 2;
                }
            }
            args.erase(args.begin() + static_cast<std::ptrdiff_t>(i),
                       args.begin() + static_cast<std::ptrdiff_t>(i) + 2);
        } else if (args[i] == "--threads" && i + 1 < args.size()) {
            threads = std::stoi(args[i + 1]);
            args.erase(args.begin() + static_cast<std::ptrdiff_t>(i),
                       args.begin() + static_cast<std::ptrdiff_t>(i) + 2);
        } else if (args[i] == "--no-check") {
            check_error = false;
            args.erase(args.begin() + static_cast<std::ptrdiff_t>(i));
        } else if (args[i] == "--phases") {
            phases = true;
            args.erase(args.begin() + static_cast<std::ptrdiff_t>(i));
        } else if (args[i] == "--json" && i + 1 < args.size()) {
            json_dir = args[i + 1];
            args.erase(args.begin() + static_cast<std::ptrdiff_t>(i),
                       args.begin() + static_cast<std::ptrdiff_t>(i) + 2);
        } else {
            ++i;
        }
    }
    if (phases && !json_dir.empty()) {
        std::cerr << "mesh_bench: --phases prints no meshes; leave out --json\n";
        return 2;
    }
    if (args.empty() || args.size() % 2 != 0) {
        std::cerr << "usage: mesh_bench [--reps N] [--effort fast|balanced|best|all] [--json DIR]"
                     " [--phases] [--threads 1|2] [--no-check] INPUT EPS[,EPS...] ...\n"
                     "  INPUT = NAME=FILE.f32:W:H | synth:SEED:W:H\n";
        return 2;
    }
    bool ok = true;
    if (phases) {
        std::cout << "input\tsize\teps\tphases_ms\ttriangles\tanchors_ms\tstart_ms"
                     "\tfirst_scan_ms\tsplit_ms\tresplit_ms\trenumber_ms\tmerge_ms\tfinish_ms"
                     "\tanchors\tsplit_triangles\tmerge_passes\tremoved\teffort\n";
    } else {
        std::cout << "input\tsize\teps\tms\ttriangles\tachieved_max_err\tpeer_triangles\tratio"
                     "\teffort\n";
    }
    for (std::size_t i = 0; i < args.size(); i += 2) {
        std::string name;
        HeightGrid g;
        if (!load(args[i], name, g)) {
            std::cerr << "mesh_bench: bad input spec " << args[i] << "\n";
            return 2;
        }
        std::stringstream ss(args[i + 1]);
        for (std::string e; std::getline(ss, e, ',');) {
            const double eps = std::stod(e);
            const std::size_t nl = levels.size();
            std::vector<std::vector<double>> times(nl);
            std::vector<tb::core::Mesh> meshes(nl);
            std::vector<tb::core::TriangulatePhases> fastest(nl);
            // Level after level within each rep, so that all see the same load.
            for (int r = 0; r < reps; ++r) {
                for (std::size_t l = 0; l < nl; ++l) {
                    tb::core::TriangulatePhases run;
                    const auto t0 = std::chrono::steady_clock::now();
                    meshes[l] = tb::core::triangulate(
                        g,
                        {.eps = eps,
                         .lock_border = true,
                         .check_error = check_error,
                         .effort = levels[l],
                         .threads = threads},
                        phases ? &run : nullptr);
                    const auto t1 = std::chrono::steady_clock::now();
                    times[l].push_back(std::chrono::duration<double, std::milli>(t1 - t0).count());
                    if (r == 0 || run.total_ms() < fastest[l].total_ms()) {
                        fastest[l] = run;
                    }
                }
            }
            for (std::size_t l = 0; l < nl; ++l) {
                const tb::core::Mesh& mesh = meshes[l];
                const char* level = tb::core::to_string(levels[l]);
                // Best of the runs: the statistic ../shared/bench/run_js_peer.mjs reports for the
                // peer, so the two are compared like for like.
                std::sort(times[l].begin(), times[l].end());
                const double err = tb::core::max_error(mesh, g);
                ok = ok && err <= eps;
                if (phases) {
                    const tb::core::TriangulatePhases& f = fastest[l];
                    std::printf("%s\t%dx%d\t%s\t%.1f\t%zu\t%.1f\t%.1f\t%.1f\t%.1f\t%.1f\t%.1f"
                                "\t%.1f\t%.1f\t%zu\t%zu\t%zu\t%zu\t%s\n",
                                name.c_str(),
                                g.width,
                                g.height,
                                e.c_str(),
                                f.total_ms(),
                                mesh.triangle_count(),
                                f.anchors_ms,
                                f.start_ms,
                                f.first_scan_ms,
                                f.split_ms,
                                f.resplit_ms,
                                f.renumber_ms,
                                f.merge_ms,
                                f.finish_ms,
                                f.anchors,
                                f.split_triangles,
                                f.merge_passes,
                                f.removed,
                                level);
                    std::fflush(stdout);
                    continue;
                }
                std::printf("%s\t%dx%d\t%s\t%.1f\t%zu\t%.6g\t-\t-\t%s\n",
                            name.c_str(),
                            g.width,
                            g.height,
                            e.c_str(),
                            times[l].front(),
                            mesh.triangle_count(),
                            err,
                            level);
                std::fflush(stdout);
                if (!json_dir.empty()) {
                    write_json(json_dir + "/" + name + "-eps" + e + "-" + level + ".json", mesh);
                }
            }
        }
    }
    return ok ? 0 : 1;
}
