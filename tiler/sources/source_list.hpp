#pragma once
// DEM inputs as users write them (command line, config): files, directories, globs and list
// files, expanded into the raster files a DemSource opens. No GDAL types here.
#include <string>
#include <vector>

namespace tb::tiler {

// The raster files named by `inputs`, in order, each at most once (first occurrence kept, compared
// by canonical path when the file exists). Throws tb::InputError (core/error.hpp) naming the input
// and what to do.
//
// Each input is, in this order of tests:
// - an existing regular file ending in .txt or .list (any case) that GDAL does not identify as
//   a raster (an ESRI ASCII grid may be named .txt): a list file, one input per line
//   (trimmed; blank lines and lines starting with '#' skipped; relative paths relative to the
//   list file's directory), each expanded as a directory, glob or file. A list file naming
//   another list file, or naming nothing, is an InputError.
// - an existing directory: every regular file under it (recursively, sorted by path; hidden
//   files and directories skipped, symlinked directories not entered) that GDAL identifies as a
//   raster, sidecars (.ovr .aux.xml .msk .xml .tfw .prj) excluded. None: InputError.
// - a missing path holding any of * ? [: a glob(3) pattern, its matches sorted, sidecars
//   skipped; a matched directory is expanded as above. No match: InputError.
// - anything else (a file, a VRT, a missing path): returned unchanged, for GDAL to open or to
//   report missing.
// An empty `inputs` gives an empty result (the caller reports that no DEM was given).
std::vector<std::string> expand_dem_inputs(const std::vector<std::string>& inputs);

// The files to watch for changes to `inputs`: as expand_dem_inputs, but every file of a
// directory (sidecars and hidden ones skipped) without asking GDAL which are rasters, so that a
// check every few seconds over thousands of files costs a stat each.
std::vector<std::string> watched_files(const std::vector<std::string>& inputs);

// Several DEMs named in one line of a message or log: the first three, and how many more.
std::string inputs_text(const std::vector<std::string>& inputs);

} // namespace tb::tiler
