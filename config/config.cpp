// Reading the server configuration. Validation collects every problem with its JSON pointer so
// a user fixes the whole file in one go instead of one error per start.
#include "config/config.hpp"

#include "core/error.hpp"
#include "tiler/log.hpp"
#include "tiler/tile_grid.hpp"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <arpa/inet.h>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <set>
#include <sstream>

namespace tb::config {
namespace {

using nlohmann::json;
namespace fs = std::filesystem;

constexpr int kMaxThreads = 256;
constexpr long long kMaxCacheMb = 1 << 20; // 1 TiB: anything larger is a typo
constexpr int kMaxQueueLimit = 100000;
constexpr int kMaxWaitMs = 600000; // ten minutes
constexpr int kMinTileSize = 2;
constexpr int kMaxTileSize = 4096;
constexpr double kMinEps = 0.001; // as tiler::check_eps
constexpr int kMaxNesting = 64;

// A short rendering of a JSON value for "got ..." in messages.
std::string show(const json& value) {
    std::string text = value.dump();
    if (text.size() > 60) {
        text = text.substr(0, 57) + "...";
    }
    return text;
}

// A key as a JSON pointer reference token (RFC 6901): "~" -> "~0", "/" -> "~1".
std::string pointer_escape(const std::string& key) {
    std::string out;
    for (char c : key) {
        out += c == '~' ? std::string("~0") : c == '/' ? std::string("~1") : std::string(1, c);
    }
    return out;
}

const char* kind(const json& value) {
    return value.type_name();
}

struct Checker {
    std::string file;
    std::vector<std::string> errors;

    void error(const std::string& pointer, const std::string& message) {
        errors.push_back(file + ": " + (pointer.empty() ? "/" : pointer) + ": " + message);
    }

    // Reports keys of `object` not in `known`.
    void known_keys(const json& object,
                    const std::string& pointer,
                    std::initializer_list<const char*> known) {
        for (auto it = object.begin(); it != object.end(); ++it) {
            bool ok = false;
            for (const char* k : known) {
                ok = ok || it.key() == k;
            }
            if (!ok) {
                std::string list;
                for (const char* k : known) {
                    list += list.empty() ? "" : ", ";
                    list += k;
                }
                error(pointer + "/" + pointer_escape(it.key()),
                      "unknown key; expected one of: " + list);
            }
        }
    }

    std::optional<long long>
    integer(const json& value, const std::string& pointer, long long lo, long long hi) {
        const std::string want =
            "expected an integer " + std::to_string(lo) + ".." + std::to_string(hi);
        if (!value.is_number_integer()) {
            error(pointer, want + ", got " + show(value));
            return std::nullopt;
        }
        if (value.is_number_unsigned() &&
            value.get<unsigned long long>() > static_cast<unsigned long long>(hi)) {
            error(pointer, want + ", got " + show(value));
            return std::nullopt;
        }
        const long long v = value.get<long long>();
        if (v < lo || v > hi) {
            error(pointer, want + ", got " + show(value));
            return std::nullopt;
        }
        return v;
    }

    // An error bound in metres: > 0, and at least the 1 mm the tiler can honour.
    std::optional<double> eps(const json& value, const std::string& pointer) {
        if (!value.is_number() || !(value.get<double>() > 0) ||
            !std::isfinite(value.get<double>())) {
            error(pointer, "expected a number > 0, got " + show(value));
            return std::nullopt;
        }
        if (value.get<double>() < kMinEps) {
            error(pointer, "expected at least 0.001 (metres), got " + show(value));
            return std::nullopt;
        }
        return value.get<double>();
    }

    // A string without NUL bytes (a path or name would be cut off at one).
    std::optional<std::string> string(const json& value, const std::string& pointer) {
        if (!value.is_string()) {
            error(pointer,
                  std::string("expected a string, got ") + kind(value) + " " + show(value));
            return std::nullopt;
        }
        if (value.get<std::string>().find('\0') != std::string::npos) {
            error(pointer, "contains a NUL byte (\\u0000), got " + show(value) + "; remove it");
            return std::nullopt;
        }
        return value.get<std::string>();
    }

    std::optional<std::string> one_of(const json& value,
                                      const std::string& pointer,
                                      std::initializer_list<const char*> choices) {
        std::string list;
        for (const char* c : choices) {
            list += list.empty() ? "" : ", ";
            list += std::string("\"") + c + "\"";
        }
        if (value.is_string()) {
            for (const char* c : choices) {
                if (value.get<std::string>() == c) {
                    return value.get<std::string>();
                }
            }
        }
        error(pointer, "expected one of " + list + ", got " + show(value));
        return std::nullopt;
    }

    bool array(const json& value, const std::string& pointer) {
        if (!value.is_array()) {
            error(pointer,
                  std::string("expected an array, got ") + kind(value) + " " + show(value));
            return false;
        }
        return true;
    }

    bool object(const json& value, const std::string& pointer) {
        if (!value.is_object()) {
            error(pointer,
                  std::string("expected an object, got ") + kind(value) + " " + show(value));
            return false;
        }
        return true;
    }
};

// GDAL names that are not local files (virtual file systems, driver prefixes) are passed on
// unchecked; Layer::open reports them if they do not open.
bool is_gdal_name(const std::string& source) {
    return source.rfind("/vsi", 0) == 0 || source.find(':') != std::string::npos;
}

std::string resolve(const fs::path& base_dir, const std::string& path) {
    if (path.empty() || is_gdal_name(path)) {
        return path;
    }
    fs::path p(path);
    if (p.is_relative()) {
        p = base_dir / p;
    }
    return p.lexically_normal().string();
}

// server/cors_origins: "*" or http(s) origins.
void parse_cors_origins(Checker& check,
                        const json& origins,
                        const std::string& at,
                        ServerConfig& out) {
    if (!check.array(origins, at)) {
        return;
    }
    out.cors_origins.clear();
    for (std::size_t i = 0; i < origins.size(); ++i) {
        const std::string pi = at + "/" + std::to_string(i);
        auto s = check.string(origins[i], pi);
        if (!s) {
            continue;
        }
        const bool ok = *s == "*" || s->rfind("http://", 0) == 0 || s->rfind("https://", 0) == 0;
        if (!ok || s->find_first_of(" \r\n\t,") != std::string::npos) {
            check.error(pi,
                        "expected \"*\" or an origin like \"https://example.com\", got " +
                            show(origins[i]));
            continue;
        }
        out.cors_origins.push_back(*s);
    }
}

// "start_wait_ms" and "deadline_ms": the wait for a start counts within the deadline, so a
// start_wait_ms above deadline_ms is an error; with deadline_ms alone, the default start wait
// is shortened to it.
void parse_waits(Checker& check, const json& value, const std::string& at, ServerConfig& out) {
    std::optional<long long> start_wait, deadline;
    if (value.contains("start_wait_ms")) {
        start_wait = check.integer(value["start_wait_ms"], at + "/start_wait_ms", 1, kMaxWaitMs);
    }
    if (value.contains("deadline_ms")) {
        deadline = check.integer(value["deadline_ms"], at + "/deadline_ms", 1, kMaxWaitMs);
    }
    if (deadline) {
        out.deadline_ms = static_cast<int>(*deadline);
        out.start_wait_ms = std::min(out.start_wait_ms, out.deadline_ms);
    }
    if (start_wait && deadline && *start_wait > *deadline) {
        check.error(at + "/start_wait_ms",
                    "expected at most deadline_ms (" + std::to_string(*deadline) + "), got " +
                        std::to_string(*start_wait) +
                        ": a request waits for its tile to start within its deadline; "
                        "lower start_wait_ms or raise deadline_ms");
    } else if (start_wait) {
        out.start_wait_ms = static_cast<int>(*start_wait);
    }
}

void parse_server(Checker& check, const json& value, ServerConfig& out) {
    const std::string at = "/server";
    if (!check.object(value, at)) {
        return;
    }
    check.known_keys(value,
                     at,
                     {"host",
                      "port",
                      "threads",
                      "cache_mb",
                      "cors_origins",
                      "log_level",
                      "queue_limit",
                      "metrics",
                      "memory_mb",
                      "start_wait_ms",
                      "deadline_ms",
                      "watch_interval_s"});
    if (value.contains("host")) {
        if (auto s = check.string(value["host"], at + "/host")) {
            if (const auto problem = host_problem(*s)) {
                check.error(at + "/host", *problem);
            } else {
                out.host = *s;
            }
        }
    }
    if (value.contains("port")) {
        if (auto v = check.integer(value["port"], at + "/port", 0, 65535)) {
            out.port = static_cast<int>(*v);
        }
    }
    if (value.contains("threads")) {
        if (auto v = check.integer(value["threads"], at + "/threads", 0, kMaxThreads)) {
            out.threads = static_cast<int>(*v);
        }
    }
    if (value.contains("cache_mb")) {
        if (auto v = check.integer(value["cache_mb"], at + "/cache_mb", 0, kMaxCacheMb)) {
            out.cache_mb = static_cast<std::size_t>(*v);
        }
    }
    if (value.contains("memory_mb")) {
        const json& v = value["memory_mb"];
        if (auto mb =
                check.integer(v, at + "/memory_mb", 0, static_cast<long long>(kMaxMemoryMb))) {
            if (*mb != 0 && *mb < static_cast<long long>(kMinMemoryMb)) {
                check.error(at + "/memory_mb",
                            "expected 0 (no budget) or at least " + std::to_string(kMinMemoryMb) +
                                ", got " + show(v));
            } else {
                out.memory_mb = static_cast<std::size_t>(*mb);
            }
        }
    }
    parse_waits(check, value, at, out);
    if (value.contains("watch_interval_s")) {
        if (auto v = check.integer(
                value["watch_interval_s"], at + "/watch_interval_s", 0, kMaxWatchIntervalS)) {
            out.watch_interval_s = static_cast<int>(*v);
        }
    }
    if (value.contains("queue_limit")) {
        if (auto v = check.integer(value["queue_limit"], at + "/queue_limit", 0, kMaxQueueLimit)) {
            out.queue_limit = static_cast<int>(*v);
        }
    }
    if (value.contains("log_level")) {
        if (auto s = check.one_of(
                value["log_level"], at + "/log_level", {"debug", "info", "warn", "error", "off"})) {
            out.log_level = *s;
        }
    }
    if (value.contains("metrics")) {
        if (auto s = check.one_of(value["metrics"], at + "/metrics", {"loopback", "on", "off"})) {
            out.metrics = *s;
        }
    }
    if (value.contains("cors_origins")) {
        parse_cors_origins(check, value["cors_origins"], at + "/cors_origins", out);
    }
}

// "summary_dir": where the DEM's summary is kept between runs; "off", or a directory resolved
// against the config's directory (made when first needed).
void parse_summary_dir(Checker& check,
                       const json& value,
                       const std::string& at,
                       const fs::path& base_dir,
                       tiler::LayerOptions& o) {
    if (!value.contains("summary_dir") || value["summary_dir"].is_null()) {
        return;
    }
    const std::string p = at + "/summary_dir";
    if (!value["summary_dir"].is_string() || value["summary_dir"].get<std::string>().empty()) {
        check.error(p, "expected null, \"off\" or a directory, got " + show(value["summary_dir"]));
    } else if (auto s = check.string(value["summary_dir"], p)) {
        o.summary_dir = *s == "off" ? *s : resolve(base_dir, *s);
    }
}

// "priority": "finest" | "listed", which of a collection's DEMs wins where they overlap.
void parse_priority(Checker& check,
                    const json& value,
                    const std::string& at,
                    tiler::LayerOptions& o) {
    if (!value.contains("priority")) {
        return;
    }
    if (auto s = check.one_of(value["priority"], at + "/priority", {"finest", "listed"})) {
        o.priority = tiler::parse_source_priority(*s, at + "/priority");
    }
}

// "valid_range": [MIN, MAX] metres, MIN < MAX; heights outside count as nodata.
void parse_valid_range(Checker& check,
                       const json& value,
                       const std::string& at,
                       tiler::LayerOptions& o) {
    if (!value.contains("valid_range")) {
        return;
    }
    const json& v = value["valid_range"];
    if (!v.is_array() || v.size() != 2 || !v[0].is_number() || !v[1].is_number() ||
        !std::isfinite(v[0].get<double>()) || !std::isfinite(v[1].get<double>()) ||
        !(v[0].get<double>() < v[1].get<double>())) {
        check.error(at + "/valid_range",
                    "expected [MIN, MAX] in metres with MIN < MAX, got " + show(v));
        return;
    }
    o.valid_range = {v[0].get<double>(), v[1].get<double>()};
}

void parse_layer(Checker& check,
                 const json& value,
                 const std::string& at,
                 const fs::path& base_dir,
                 LayerConfig& out) {
    if (!check.object(value, at)) {
        return;
    }
    check.known_keys(value,
                     at,
                     {"name",
                      "sources",
                      "scheme",
                      "tile_size",
                      "min_zoom",
                      "max_zoom",
                      "finest_eps",
                      "eps_levels",
                      "datum",
                      "formats",
                      "store",
                      "dem_tile_size",
                      "dem_heights",
                      "nodata",
                      "effort",
                      "summary_dir",
                      "valid_range",
                      "priority"});
    tiler::LayerOptions& o = out.options;

    if (!value.contains("name")) {
        check.error(at + "/name", "missing; give the layer a URL-safe name like \"alps\"");
    } else if (auto s = check.string(value["name"], at + "/name")) {
        if (!is_valid_layer_name(*s)) {
            check.error(at + "/name",
                        "expected 1..64 characters of A-Z a-z 0-9 _ -, got " + show(value["name"]));
        } else {
            o.name = *s;
        }
    }

    if (!value.contains("sources")) {
        check.error(at + "/sources", "missing; list the DEM files of the layer");
    } else if (check.array(value["sources"], at + "/sources")) {
        const json& sources = value["sources"];
        if (sources.empty()) {
            check.error(at + "/sources", "expected at least one DEM path, got []");
        }
        for (std::size_t i = 0; i < sources.size(); ++i) {
            const std::string pi = at + "/sources/" + std::to_string(i);
            auto s = check.string(sources[i], pi);
            if (!s) {
                continue;
            }
            if (s->empty()) {
                check.error(pi, "expected a DEM path, got \"\"");
                continue;
            }
            const std::string path = resolve(base_dir, *s);
            // A directory, a list file or a glob names a collection: expanded when the layer
            // opens (tiler/sources/source_list.hpp), which reports what it finds wrong.
            const bool glob = path.find_first_of("*?[") != std::string::npos;
            std::error_code ec;
            if (!is_gdal_name(path) && !glob && !fs::exists(path, ec)) {
                check.error(pi, "file not found: " + path);
                continue;
            }
            o.sources.push_back(path);
        }
    }

    if (value.contains("scheme")) {
        if (auto s = check.one_of(value["scheme"], at + "/scheme", {"geodetic", "mercator"})) {
            o.scheme = tiler::parse_scheme(*s);
        }
    }
    if (value.contains("tile_size")) {
        if (auto v =
                check.integer(value["tile_size"], at + "/tile_size", kMinTileSize, kMaxTileSize)) {
            o.tile_size = static_cast<int>(*v);
        }
    }
    if (value.contains("min_zoom") && !value["min_zoom"].is_null()) {
        if (auto v = check.integer(value["min_zoom"], at + "/min_zoom", 0, tiler::kMaxZoom)) {
            o.min_zoom = static_cast<int>(*v);
        }
    }
    if (value.contains("max_zoom") && !value["max_zoom"].is_null()) {
        if (auto v = check.integer(value["max_zoom"], at + "/max_zoom", 0, tiler::kMaxZoom)) {
            o.max_zoom = static_cast<int>(*v);
        }
    }
    if (o.min_zoom && o.max_zoom && *o.min_zoom > *o.max_zoom) {
        check.error(at + "/max_zoom",
                    "expected max_zoom >= min_zoom (" + std::to_string(*o.min_zoom) + "), got " +
                        std::to_string(*o.max_zoom));
    }
    if (value.contains("finest_eps") && !value["finest_eps"].is_null()) {
        if (auto v = check.eps(value["finest_eps"], at + "/finest_eps")) {
            o.finest_eps = *v;
        }
    }
    if (value.contains("eps_levels") && check.array(value["eps_levels"], at + "/eps_levels")) {
        const json& levels = value["eps_levels"];
        for (std::size_t i = 0; i < levels.size(); ++i) {
            if (auto v = check.eps(levels[i], at + "/eps_levels/" + std::to_string(i))) {
                o.eps_levels.push_back(*v);
            }
        }
    }
    if (value.contains("effort")) {
        if (auto s = check.one_of(value["effort"], at + "/effort", {"fast", "balanced", "best"})) {
            o.effort = core::parse_effort(*s);
        }
    }
    if (value.contains("datum")) {
        if (auto s = check.one_of(value["datum"], at + "/datum", {"auto", "egm96", "ellipsoid"})) {
            o.datum = *s == "egm96"       ? tiler::VerticalDatum::Egm96
                      : *s == "ellipsoid" ? tiler::VerticalDatum::Ellipsoid
                                          : tiler::VerticalDatum::Auto;
        }
    }
    if (value.contains("formats") && check.array(value["formats"], at + "/formats")) {
        const json& formats = value["formats"];
        out.formats.clear();
        if (formats.empty()) {
            check.error(at + "/formats",
                        "expected at least one of \"glb\", \"drc\", \"terrarium\", "
                        "\"mapbox\", \"terrain\", \"terrain3d\", got []");
        }
        for (std::size_t i = 0; i < formats.size(); ++i) {
            const std::string pi = at + "/formats/" + std::to_string(i);
            if (auto s =
                    check.one_of(formats[i],
                                 pi,
                                 {"glb", "drc", "terrarium", "mapbox", "terrain", "terrain3d"})) {
                const tiler::Format f = *tiler::parse_format(*s);
                bool seen = false;
                for (auto g : out.formats) {
                    seen = seen || g == f;
                }
                if (seen) {
                    check.error(pi, "duplicate format " + show(formats[i]));
                } else {
                    out.formats.push_back(f);
                }
            }
        }
    }
    if (value.contains("dem_tile_size")) {
        const std::string p = at + "/dem_tile_size";
        if (auto v = check.integer(value["dem_tile_size"], p, 256, 512)) {
            if (*v != 256 && *v != 512) {
                check.error(p, "expected 256 or 512, got " + show(value["dem_tile_size"]));
            } else {
                o.dem_tile_size = static_cast<int>(*v);
            }
        }
    }
    if (value.contains("dem_heights")) {
        if (auto s = check.one_of(
                value["dem_heights"], at + "/dem_heights", {"sea_level", "ellipsoid"})) {
            o.dem_heights =
                *s == "ellipsoid" ? tiler::DemHeights::Ellipsoid : tiler::DemHeights::SeaLevel;
        }
    }
    if (value.contains("nodata") && !value["nodata"].is_null()) {
        const json& v = value["nodata"];
        if (!v.is_number() || !std::isfinite(v.get<double>())) {
            check.error(at + "/nodata",
                        "expected null or the raw sample value of voids (a number), got " +
                            show(v));
        } else {
            o.nodata = v.get<double>();
        }
    }
    parse_summary_dir(check, value, at, base_dir, o);
    parse_valid_range(check, value, at, o);
    parse_priority(check, value, at, o);
    if (value.contains("store") && !value["store"].is_null()) {
        const std::string p = at + "/store";
        if (!value["store"].is_string()) {
            check.error(p,
                        std::string("expected null or a path (a directory, or a file ending in "
                                    ".sqlite or .db), got ") +
                            show(value["store"]));
        } else if (value["store"].get<std::string>().empty()) {
            check.error(p, "expected null or a path, got \"\"");
        } else if (!check.string(value["store"], p)) {
            // a NUL byte, reported
        } else {
            const std::string path = resolve(base_dir, value["store"].get<std::string>());
            const fs::path parent = fs::path(path).parent_path();
            std::error_code ec;
            if (!parent.empty() && !fs::is_directory(parent, ec)) {
                check.error(p,
                            "directory " + parent.string() +
                                " does not exist; create it or fix the path");
            } else {
                out.store = path;
            }
        }
    }
}

// Refuses arrays and objects nested deeper than any config needs, before parsing: a value
// nested 100,000 deep would exhaust the stack of everything that walks it recursively.
void check_nesting(const std::string& text, const std::string& path) {
    int depth = 0, line = 1;
    bool in_string = false, escaped = false;
    for (char c : text) {
        if (c == '\n') {
            ++line;
        }
        if (in_string) {
            if (escaped) {
                escaped = false;
            } else if (c == '\\') {
                escaped = true;
            } else if (c == '"') {
                in_string = false;
            }
            continue;
        }
        if (c == '"') {
            in_string = true;
        } else if (c == '[' || c == '{') {
            if (++depth > kMaxNesting) {
                throw InputError(path + ": line " + std::to_string(line) +
                                 ": arrays and objects nested more than " +
                                 std::to_string(kMaxNesting) +
                                 " deep; a config nests 4 levels at most, fix the file");
            }
        } else if (c == ']' || c == '}') {
            --depth;
        }
    }
}

} // namespace

std::optional<std::string> host_problem(const std::string& host) {
    const std::string got = " got \"" + host.substr(0, 80) + "\"";
    if (host.empty()) {
        return "expected a host name or address, got \"\"";
    }
    unsigned char buffer[sizeof(in6_addr)];
    if (host.find(':') != std::string::npos) {
        if (inet_pton(AF_INET6, host.c_str(), buffer) != 1) {
            return "expected an IPv6 address such as \"::1\" (it holds ':');" + got;
        }
        return std::nullopt;
    }
    if (host.find_first_not_of("0123456789.") == std::string::npos) {
        if (inet_pton(AF_INET, host.c_str(), buffer) != 1) {
            return "expected an IPv4 address: four numbers 0..255 joined by '.', such as "
                   "\"127.0.0.1\";" +
                   got;
        }
        return std::nullopt;
    }
    bool ok = host.size() <= 253;
    std::size_t start = 0;
    while (ok && start <= host.size()) {
        std::size_t end = host.find('.', start);
        if (end == std::string::npos) {
            end = host.size();
        }
        const std::string label = host.substr(start, end - start);
        ok = !label.empty() && label.size() <= 63 && label.front() != '-' && label.back() != '-';
        for (char c : label) {
            ok = ok && ((c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') ||
                        (c >= '0' && c <= '9') || c == '-');
        }
        start = end + 1;
    }
    if (!ok) {
        return "expected a host name (letters, digits and '-' in '.'-separated parts) or an IP "
               "address;" +
               got;
    }
    return std::nullopt;
}

bool is_valid_layer_name(const std::string& name) {
    if (name.empty() || name.size() > 64) {
        return false;
    }
    for (char c : name) {
        const bool ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') ||
                        (c >= '0' && c <= '9') || c == '_' || c == '-';
        if (!ok) {
            return false;
        }
    }
    return true;
}

std::string layer_name_from_path(const std::string& path) {
    std::string stem = fs::path(path).filename().string();
    // Strip every extension: "N48W125.hgt.zip" -> "N48W125".
    const auto dot = stem.find('.');
    if (dot != std::string::npos && dot > 0) {
        stem = stem.substr(0, dot);
    }
    std::string name;
    for (char c : stem) {
        const bool ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') ||
                        (c >= '0' && c <= '9') || c == '_' || c == '-';
        if (ok) {
            name += c;
        } else if (!name.empty() && name.back() != '_') {
            name += '_';
        }
    }
    while (!name.empty() && name.back() == '_') {
        name.pop_back();
    }
    if (name.size() > 64) {
        name.resize(64);
    }
    return name.empty() ? "terrain" : name;
}

Config parse_config(const std::string& text, const std::string& path) {
    Checker check{path, {}};
    check_nesting(text, path);
    json root;
    try {
        root = json::parse(text);
    } catch (const json::exception& e) {
        // e.what() is "[json.exception.parse_error.101] parse error at line 3, column 5: ...",
        // or out_of_range.406 for a number too large for a double ("2e308").
        std::string what = e.what();
        const auto close = what.find("] ");
        if (close != std::string::npos) {
            what = what.substr(close + 2);
        }
        throw InputError(path + ": not valid JSON: " + what);
    }

    Config config;
    if (!check.object(root, "")) {
        throw InputError(check.errors.front());
    }
    check.known_keys(root, "", {"server", "layers"});
    if (root.contains("server")) {
        parse_server(check, root["server"], config.server);
    }
    const fs::path base_dir = fs::absolute(fs::path(path)).parent_path();
    if (!root.contains("layers")) {
        check.error("/layers", "missing; a config needs at least one layer");
    } else if (check.array(root["layers"], "/layers")) {
        const json& layers = root["layers"];
        if (layers.empty()) {
            check.error("/layers", "expected at least one layer, got []");
        }
        std::map<std::string, std::size_t> names;
        for (std::size_t i = 0; i < layers.size(); ++i) {
            const std::string at = "/layers/" + std::to_string(i);
            LayerConfig layer;
            parse_layer(check, layers[i], at, base_dir, layer);
            if (layers[i].is_object() && layers[i].contains("name") &&
                layers[i]["name"].is_string() &&
                is_valid_layer_name(layers[i]["name"].get<std::string>())) {
                const auto [it, fresh] = names.emplace(layer.options.name, i);
                if (!fresh) {
                    check.error(at + "/name",
                                "duplicate layer name \"" + layer.options.name +
                                    "\" (also /layers/" + std::to_string(it->second) + "/name)");
                }
            }
            config.layers.push_back(std::move(layer));
        }
    }
    if (!check.errors.empty()) {
        std::string message;
        for (const auto& e : check.errors) {
            message += message.empty() ? "" : "\n";
            message += e;
        }
        if (check.errors.size() > 1) {
            message =
                std::to_string(check.errors.size()) + " problems in " + path + ":\n" + message;
        }
        throw InputError(message);
    }
    return config;
}

Config load_config(const std::string& path) {
    std::error_code ec;
    if (fs::is_directory(path, ec)) {
        throw InputError(path + ": is a directory; expected a JSON config file");
    }
    std::ifstream in(path, std::ios::binary);
    if (!in) {
        throw InputError(path + ": cannot read the config file; check the path");
    }
    std::ostringstream text;
    text << in.rdbuf();
    return parse_config(text.str(), path);
}

} // namespace tb::config
