// DEM inputs expanded into raster files (source_list.hpp): list files, directories and globs.
#include "tiler/sources/source_list.hpp"

#include "core/error.hpp"
#include "tiler/sources/gdal_source.hpp"

#include <gdal.h>

#include <glob.h>

#include <algorithm>
#include <cctype>
#include <filesystem>
#include <fstream>
#include <initializer_list>
#include <set>
#include <string_view>
#include <system_error>

namespace tb::tiler {
namespace {

namespace fs = std::filesystem;

// The files found so far, in order, and the identities of those already taken.
struct Found {
    std::vector<std::string> paths;
    std::set<std::string> seen;
    bool identify = true; // a directory's files: only those GDAL identifies as rasters
};

// A path with a NUL in it would be cut short by every system call (naming some other file), so
// it is never looked at here: it passes through for GDAL to reject with its own message.
bool has_nul(const std::string& path) {
    return path.find('\0') != std::string::npos;
}

void add(Found& found, const std::string& path) {
    std::error_code ec;
    const fs::path canonical = has_nul(path) ? fs::path() : fs::canonical(path, ec);
    // A missing file has no canonical form, so its spelling is its identity.
    const std::string key = canonical.empty() ? path : canonical.string();
    if (found.seen.insert(key).second) {
        found.paths.push_back(path);
    }
}

bool ends_with_any(const std::string& name, std::initializer_list<std::string_view> suffixes) {
    std::string lower = name;
    std::transform(lower.begin(), lower.end(), lower.begin(), [](unsigned char c) {
        return static_cast<char>(std::tolower(c));
    });
    return std::any_of(
        suffixes.begin(), suffixes.end(), [&](std::string_view s) { return lower.ends_with(s); });
}

// A raster GDAL recognizes (an ESRI ASCII grid may be named .txt).
bool is_raster(const std::string& path) {
    init_gdal();
    return GDALIdentifyDriverEx(path.c_str(), GDAL_OF_RASTER, nullptr, nullptr) != nullptr;
}

bool is_list_file(const std::string& path) {
    std::error_code ec;
    return !has_nul(path) && fs::is_regular_file(path, ec) &&
           ends_with_any(fs::path(path).filename().string(), {".txt", ".list"}) && !is_raster(path);
}

// Files that sit beside rasters and describe them (overviews, PAM metadata, masks, world files,
// projections): GDAL identifies some of these as rasters too. Notes and list files (.txt) are
// skipped by a directory's expansion because GDAL does not identify them.
bool is_sidecar(const std::string& name) {
    return ends_with_any(name, {".ovr", ".aux.xml", ".msk", ".xml", ".tfw", ".prj"});
}

// glob(3) reads a backslash as an escape, so a directory named with * ? [ stays literal.
std::string escape_glob(const std::string& text) {
    std::string out;
    for (const char c : text) {
        if (c == '*' || c == '?' || c == '[' || c == '\\') {
            out += '\\';
        }
        out += c;
    }
    return out;
}

// Every raster file under `dir`. Symlinked directories are not entered (a link back up the tree
// would never end); symlinked files are taken, and add() drops them when their target is too.
void expand_directory(const std::string& dir, Found& found) {
    std::vector<fs::path> files;
    std::error_code ec;
    for (fs::recursive_directory_iterator it(dir, ec);
         !ec && it != fs::recursive_directory_iterator();
         it.increment(ec)) {
        const std::string name = it->path().filename().string();
        if (name.starts_with('.')) {
            it.disable_recursion_pending();
            continue;
        }
        std::error_code type_ec;
        if (it->is_regular_file(type_ec) && !is_sidecar(name)) {
            files.push_back(it->path());
        }
    }
    if (ec) {
        throw InputError(dir + ": cannot be read (" + ec.message() +
                         "); check its permissions or give the DEM files");
    }
    // The directory's own order depends on the file system; the output must not.
    std::sort(files.begin(), files.end());
    bool any = false;
    for (const fs::path& file : files) {
        if (!found.identify || is_raster(file.string())) {
            add(found, file.string());
            any = true;
        }
    }
    if (!any) {
        throw InputError(dir +
                         ": holds no raster GDAL can read; give the DEM files or a directory that "
                         "holds them");
    }
}

// `pattern` is what glob(3) gets, `shown` how the user wrote it.
void expand_glob(const std::string& pattern, const std::string& shown, Found& found) {
    glob_t g{};
    const int rc = ::glob(pattern.c_str(), 0, nullptr, &g);
    std::vector<std::string> matches;
    if (rc == 0) {
        matches.assign(g.gl_pathv, g.gl_pathv + g.gl_pathc);
    }
    ::globfree(&g);
    if (rc == GLOB_NOMATCH || (rc == 0 && matches.empty())) {
        throw InputError(shown + ": matches no file; check the pattern and the directory it names");
    }
    if (rc != 0) {
        throw InputError(shown + ": " +
                         (rc == GLOB_ABORTED ? "a directory it searches cannot be read"
                                             : "cannot be searched (out of memory)") +
                         "; check the directory's permissions or give the DEM files");
    }
    for (const std::string& match : matches) {
        std::error_code ec;
        if (fs::is_directory(match, ec)) {
            expand_directory(match, found);
        } else if (!is_sidecar(fs::path(match).filename().string())) {
            add(found, match); // 'dems/*' names the .aux.xml and .ovr beside each DEM too
        }
    }
}

// One input that is not a list file: a directory, a glob, or a file passed through.
void expand_entry(const std::string& path, const std::string& pattern, Found& found) {
    std::error_code ec;
    const fs::file_status status =
        has_nul(path) ? fs::file_status(fs::file_type::unknown) : fs::status(path, ec);
    if (fs::is_directory(status)) {
        expand_directory(path, found);
    } else if (!fs::exists(status) && path.find_first_of("*?[") != std::string::npos) {
        expand_glob(pattern, path, found);
    } else {
        add(found, path);
    }
}

void expand_list_file(const std::string& list, Found& found) {
    std::ifstream in(list);
    if (!in) {
        throw InputError(list + ": cannot be read; check its permissions");
    }
    const fs::path base = fs::path(list).parent_path();
    std::string line;
    int number = 0, entries = 0;
    while (std::getline(in, line)) {
        ++number;
        const std::size_t first = line.find_first_not_of(" \t\r\n\f\v");
        if (first == std::string::npos || line[first] == '#') {
            continue;
        }
        const std::size_t last = line.find_last_not_of(" \t\r\n\f\v");
        const std::string entry = line.substr(first, last - first + 1);
        ++entries;
        const bool relative = !base.empty() && fs::path(entry).is_relative();
        const std::string path = relative ? (base / entry).string() : entry;
        const std::string where = list + ":" + std::to_string(number) + ": ";
        if (is_list_file(path)) {
            throw InputError(where + path +
                             " is a list file, and a list file cannot name another; list the "
                             "DEMs, directories or globs it holds here instead");
        }
        const std::string pattern =
            relative ? (fs::path(escape_glob(base.string())) / entry).string() : entry;
        try {
            expand_entry(path, pattern, found);
        } catch (const InputError& e) {
            throw InputError(where + e.what());
        }
    }
    if (in.bad()) {
        throw InputError(list + ": cannot be read to the end; check the file");
    }
    if (entries == 0) {
        throw InputError(list +
                         ": names no DEM (only blank lines and comments); list one DEM file, "
                         "directory or glob per line");
    }
}

std::vector<std::string> expand_into(const std::vector<std::string>& inputs, Found& found) {
    for (const std::string& input : inputs) {
        if (is_list_file(input)) {
            expand_list_file(input, found);
        } else {
            expand_entry(input, input, found);
        }
    }
    return found.paths;
}

} // namespace

std::vector<std::string> expand_dem_inputs(const std::vector<std::string>& inputs) {
    Found found;
    return expand_into(inputs, found);
}

std::vector<std::string> watched_files(const std::vector<std::string>& inputs) {
    Found found;
    found.identify = false;
    return expand_into(inputs, found);
}

std::string inputs_text(const std::vector<std::string>& inputs) {
    std::string text;
    for (std::size_t i = 0; i < inputs.size() && i < 3; ++i) {
        text += (i ? ", " : "") + inputs[i];
    }
    if (inputs.size() > 3) {
        text += " and " + std::to_string(inputs.size() - 3) + " more";
    }
    return text;
}

} // namespace tb::tiler
