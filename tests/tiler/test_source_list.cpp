// expand_dem_inputs: DEM inputs given as files, directories, globs and list files, expanded over
// real small GeoTIFFs in a temp dir, with exact expected lists and error messages.
#include "core/error.hpp"
#include "tests/tiler/test_raster_util.hpp"
#include "tiler/sources/source_list.hpp"

#include <doctest/doctest.h>

#include <filesystem>
#include <string>
#include <vector>

using tb::tiler::expand_dem_inputs;
using tb_test::Fixture;
using tb_test::ScratchDir;
namespace fs = std::filesystem;

namespace {

using Paths = std::vector<std::string>;

// A 4 x 4 GeoTIFF at `path` (its directories made first); returns the path.
std::string tif(const fs::path& path) {
    fs::create_directories(path.parent_path());
    return tb_test::write_fixture(path.string(), Fixture{});
}

// A text file at `path` holding `body`; returns the path.
std::string text(const fs::path& path, const std::string& body) {
    fs::create_directories(path.parent_path());
    tb_test::spill(path, body);
    return path.string();
}

// The message of the InputError that expanding `inputs` throws ("" when none is thrown).
std::string error_of(const Paths& inputs) {
    try {
        expand_dem_inputs(inputs);
    } catch (const tb::InputError& e) {
        return e.what();
    }
    return "";
}

} // namespace

TEST_CASE("source list gives nothing for no input") {
    CHECK(expand_dem_inputs({}).empty());
}

TEST_CASE("source list expands a directory recursively and sorted, rasters only") {
    const ScratchDir dir;
    const fs::path dems = dir.path / "dems";
    tif(dems / "b.tif");
    tif(dems / "a.tif");
    tif(dems / "sub" / "c.tif");
    tif(dems / "a-z.tif");
    tif(dems / "sub-x.tif");
    // Sidecars GDAL would read as rasters (an .ovr is a GeoTIFF) or as metadata, hidden files
    // and directories, and files that are no raster at all are left out.
    tif(dems / "a.tif.ovr");
    text(dems / "a.tif.aux.xml", "<PAMDataset></PAMDataset>\n");
    text(dems / "b.TFW", "1\n0\n0\n-1\n0\n0\n");
    tif(dems / ".hidden.tif");
    tif(dems / ".cache" / "d.tif");
    text(dems / "README.md", "# the DEMs of the test\n");
    text(dems / "sub" / "notes.txt", "sub/c.tif\n");

    // Sorted by path, component by component, whatever order the file system lists them in: a
    // directory's files stay together, so sub/c.tif comes before sub-x.tif.
    const Paths expected{(dems / "a-z.tif").string(),
                         (dems / "a.tif").string(),
                         (dems / "b.tif").string(),
                         (dems / "sub" / "c.tif").string(),
                         (dems / "sub-x.tif").string()};
    CHECK(expand_dem_inputs({dems.string()}) == expected);
}

TEST_CASE("source list expands a glob, sorted, sidecars skipped, and a directory it matches as "
          "a directory") {
    const ScratchDir dir;
    const fs::path d = dir.path / "d";
    tif(d / "x2.tif");
    tif(d / "x1.tif");
    tif(d / "y.tif");
    tif(d / "set" / "s2.tif");
    tif(d / "set" / "s1.tif");
    text(d / "set" / "s1.tif.aux.xml", "<PAMDataset></PAMDataset>\n");

    const Paths expected{(d / "x1.tif").string(),
                         (d / "x2.tif").string(),
                         (d / "set" / "s1.tif").string(),
                         (d / "set" / "s2.tif").string()};
    CHECK(expand_dem_inputs({(d / "x?.tif").string(), (d / "s*").string()}) == expected);
    // Files a glob matches skip sidecars as a directory's do.
    text(d / "y.tif.aux.xml", "<PAMDataset></PAMDataset>\n");
    text(d / "y.tif.ovr", "");
    CHECK(expand_dem_inputs({(d / "y*").string()}) == Paths{(d / "y.tif").string()});
}

TEST_CASE("source list reads a list file with comments, relative paths, a directory and a glob") {
    const ScratchDir dir;
    // Glob characters in the list file's own directory name stay literal in its glob lines.
    const fs::path set = dir.path / "set [2020]";
    tif(set / "one.tif");
    tif(set / "more" / "m2.tif");
    tif(set / "more" / "m1.tif");
    tif(set / "g1.tif");
    tif(set / "g2.tif");
    const std::string two = tif(dir.path / "two.tif");
    const std::string list = text(set / "dems.LIST",
                                  "# the 2020 survey\n"
                                  "\n"
                                  "   one.tif   \n"
                                  "more\r\n"
                                  "\t# tiles from elsewhere\n" +
                                      two +
                                      "\n"
                                      "g*.tif");

    const Paths expected{(set / "one.tif").string(),
                         (set / "more" / "m1.tif").string(),
                         (set / "more" / "m2.tif").string(),
                         two,
                         (set / "g1.tif").string(),
                         (set / "g2.tif").string()};
    CHECK(expand_dem_inputs({list}) == expected);
}

TEST_CASE("source list keeps each file once, as first named") {
    const ScratchDir dir;
    const fs::path dems = dir.path / "dems";
    tif(dems / "a.tif");
    tif(dems / "b.tif");
    tif(dems / "c.tif");
    const std::string list = text(dir.path / "list.txt", "dems/./a.tif\ndems/b.tif\n");
    const std::string missing = (dir.path / "missing.tif").string();

    const Paths expected{(dems / "b.tif").string(),
                         (dir.path / "dems/./a.tif").string(),
                         missing,
                         (dems / "c.tif").string()};
    CHECK(expand_dem_inputs({(dems / "b.tif").string(), list, missing, missing, dems.string()}) ==
          expected);
}

TEST_CASE("source list passes files and missing plain paths through unchanged") {
    const ScratchDir dir;
    const std::string a = tif(dir.path / "a.tif");
    const Paths inputs{(dir.path / "missing.tif").string(), "no/such/dem.vrt", a};
    CHECK(expand_dem_inputs(inputs) == inputs);
}

TEST_CASE("source list rejects a list file naming another list file") {
    const ScratchDir dir;
    tif(dir.path / "a.tif");
    text(dir.path / "inner.list", "a.tif\n");
    const std::string outer = text(dir.path / "outer.txt", "a.tif\n# then\ninner.list\n");
    CHECK(error_of({outer}) == outer + ":3: " + (dir.path / "inner.list").string() +
                                   " is a list file, and a list file cannot name another; list "
                                   "the DEMs, directories or globs it holds here instead");
}

TEST_CASE("source list rejects a list file naming nothing") {
    const ScratchDir dir;
    const std::string list = text(dir.path / "dems.txt", "# nothing yet\n\n   \n");
    CHECK(error_of({list}) == list + ": names no DEM (only blank lines and comments); list one "
                                     "DEM file, directory or glob per line");
}

TEST_CASE("source list rejects a directory holding no raster") {
    const ScratchDir dir;
    const fs::path empty = dir.path / "empty";
    fs::create_directories(empty);
    CHECK(error_of({empty.string()}) ==
          empty.string() + ": holds no raster GDAL can read; give the DEM files or a directory "
                           "that holds them");

    // Only sidecars, notes and hidden rasters: still nothing to read.
    const fs::path notes = dir.path / "notes";
    text(notes / "README.md", "# DEMs go here\n");
    text(notes / "a.tif.aux.xml", "<PAMDataset></PAMDataset>\n");
    tif(notes / ".hidden.tif");
    CHECK(error_of({notes.string()}) ==
          notes.string() + ": holds no raster GDAL can read; give the DEM files or a directory "
                           "that holds them");
}

TEST_CASE("source list rejects a glob matching nothing, naming the list line it is on") {
    const ScratchDir dir;
    tif(dir.path / "a.tif");
    const std::string pattern = (dir.path / "*.hgt").string();
    CHECK(error_of({pattern}) ==
          pattern + ": matches no file; check the pattern and the directory it names");

    const std::string list = text(dir.path / "dems.txt", "a.tif\nn*.tif\n");
    CHECK(error_of({list}) == list + ":2: " + (dir.path / "n*.tif").string() +
                                  ": matches no file; check the pattern and the directory it "
                                  "names");
}

TEST_CASE("source list takes an ESRI ASCII grid named .txt as a raster, not as a list file") {
    const ScratchDir dir;
    const std::string grid = text(dir.path / "grids" / "grid.txt",
                                  "ncols 2\nnrows 2\nxllcorner 0\nyllcorner 0\ncellsize 1\n"
                                  "1 2\n3 4\n");
    CHECK(expand_dem_inputs({grid}) == Paths{grid});
    CHECK(expand_dem_inputs({(dir.path / "grids").string()}) == Paths{grid});
}

TEST_CASE("source list watches every file of a directory without asking GDAL, sidecars and hidden "
          "files skipped") {
    const ScratchDir dir;
    const fs::path d = dir.path / "d";
    const std::string a = tif(d / "a.tif");
    const std::string notes = text(d / "notes.md", "not a raster\n");
    text(d / "a.tif.aux.xml", "<PAMDataset></PAMDataset>\n");
    text(d / ".hidden.tif", "");
    CHECK(tb::tiler::watched_files({d.string()}) == Paths{a, notes});
    CHECK(expand_dem_inputs({d.string()}) == Paths{a});
}
