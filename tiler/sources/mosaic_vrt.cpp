#include "tiler/sources/mosaic_vrt.hpp"

#include "core/error.hpp"

#include <cpl_conv.h>
#include <cpl_minixml.h>
#include <gdal.h>
#include <ogr_spatialref.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>

namespace tb::tiler {
namespace {

struct XmlDeleter {
    void operator()(CPLXMLNode* node) const { CPLDestroyXMLNode(node); }
};

// A number as GDAL reads it back exactly; NaN as "nan".
std::string number(double v) {
    if (std::isnan(v)) {
        return "nan";
    }
    char text[40];
    std::snprintf(text, sizeof text, "%.17g", v);
    return text;
}

// A pixel offset or size that is an integer but for a rounding is that integer, so that GDAL
// reads the file's pixels as they are instead of resampling them by a hair.
double snapped(double v) {
    const double r = std::round(v);
    return std::abs(v - r) < 1e-6 ? r : v;
}

// The mosaic's pixel size along one axis: the files' own when they agree, else their mean.
double pixel_size(const std::vector<const FileScan*>& files, int k) {
    double sum = 0;
    bool equal = true;
    for (const FileScan* f : files) {
        sum += f->info.geotransform[k];
        equal = equal && f->info.geotransform[k] == files.front()->info.geotransform[k];
    }
    return equal ? files.front()->info.geotransform[k] : sum / static_cast<double>(files.size());
}

void add_rect(CPLXMLNode* parent, const char* name, double x, double y, double w, double h) {
    CPLXMLNode* rect = CPLCreateXMLNode(parent, CXT_Element, name);
    CPLAddXMLAttributeAndValue(rect, "xOff", number(x).c_str());
    CPLAddXMLAttributeAndValue(rect, "yOff", number(y).c_str());
    CPLAddXMLAttributeAndValue(rect, "xSize", number(w).c_str());
    CPLAddXMLAttributeAndValue(rect, "ySize", number(h).c_str());
}

struct Frame {
    double west, north, dx, dy; // the mosaic's origin and pixel size (dy < 0)
};

// One file's source element: where its pixels land in the mosaic, what it is, its nodata, and
// its scale and offset when the band cannot carry one for all.
void add_source(CPLXMLNode* band, const FileScan& f, const Frame& m, bool own_scale) {
    const DemInfo& info = f.info;
    const bool complex = info.nodata.has_value() || own_scale;
    CPLXMLNode* source =
        CPLCreateXMLNode(band, CXT_Element, complex ? "ComplexSource" : "SimpleSource");
    const std::string path =
        info.path.starts_with("/vsi") ? info.path : std::filesystem::absolute(info.path).string();
    CPLXMLNode* name = CPLCreateXMLElementAndValue(source, "SourceFilename", path.c_str());
    CPLAddXMLAttributeAndValue(name, "relativeToVRT", "0");
    CPLCreateXMLElementAndValue(source, "SourceBand", "1");
    CPLXMLNode* props = CPLCreateXMLNode(source, CXT_Element, "SourceProperties");
    CPLAddXMLAttributeAndValue(props, "RasterXSize", std::to_string(info.width).c_str());
    CPLAddXMLAttributeAndValue(props, "RasterYSize", std::to_string(info.height).c_str());
    CPLAddXMLAttributeAndValue(props, "DataType", info.data_type.c_str());
    CPLAddXMLAttributeAndValue(props, "BlockXSize", std::to_string(f.block_width).c_str());
    CPLAddXMLAttributeAndValue(props, "BlockYSize", std::to_string(f.block_height).c_str());
    const auto& g = info.geotransform;
    add_rect(source, "SrcRect", 0, 0, info.width, info.height);
    add_rect(source,
             "DstRect",
             snapped((g[0] - m.west) / m.dx),
             snapped((g[3] - m.north) / m.dy),
             snapped(info.width * g[1] / m.dx),
             snapped(info.height * g[5] / m.dy));
    if (info.nodata) {
        CPLCreateXMLElementAndValue(source, "NODATA", number(*info.nodata).c_str());
    }
    if (own_scale) {
        CPLCreateXMLElementAndValue(source, "ScaleOffset", number(info.offset).c_str());
        CPLCreateXMLElementAndValue(source, "ScaleRatio", number(info.scale).c_str());
    }
}

// Overviews of the mosaic drawn from its files' own, at the factors every file has.
void add_overview_list(CPLXMLNode* root, const std::vector<const FileScan*>& files) {
    std::vector<int> common = files.front()->overview_factors;
    for (const FileScan* f : files) {
        std::erase_if(common, [&](int factor) {
            return std::find(f->overview_factors.begin(), f->overview_factors.end(), factor) ==
                   f->overview_factors.end();
        });
    }
    std::string list;
    for (int factor : common) {
        list += list.empty() ? "" : " ";
        list += std::to_string(factor);
    }
    if (!list.empty()) {
        CPLXMLNode* node = CPLCreateXMLElementAndValue(root, "OverviewList", list.c_str());
        CPLAddXMLAttributeAndValue(node, "resampling", "nearest");
    }
}

} // namespace

std::string mosaic_vrt_xml(const std::vector<const FileScan*>& files, double nodata) {
    TB_ASSERT(!files.empty());
    Frame m{INFINITY, -INFINITY, pixel_size(files, 1), pixel_size(files, 5)};
    double east = -INFINITY, south = INFINITY;
    GDALDataType type = GDT_Unknown;
    const bool same_scale = shares_scale(files);
    for (const FileScan* f : files) {
        const auto& g = f->info.geotransform;
        if (!(g[1] > 0) || !(g[5] < 0)) {
            throw InputError(f->info.path + ": only north-up rasters are mosaicked; warp it "
                                            "first (gdalwarp) or give it alone");
        }
        m.west = std::min(m.west, g[0]), m.north = std::max(m.north, g[3]);
        east = std::max(east, g[0] + f->info.width * g[1]);
        south = std::min(south, g[3] + f->info.height * g[5]);
        const GDALDataType t = GDALGetDataTypeByName(f->info.data_type.c_str());
        type = type == GDT_Unknown ? t : GDALDataTypeUnion(type, t);
    }
    std::unique_ptr<CPLXMLNode, XmlDeleter> root(
        CPLCreateXMLNode(nullptr, CXT_Element, "VRTDataset"));
    const long long width = std::max(1LL, std::llround((east - m.west) / m.dx));
    const long long height = std::max(1LL, std::llround((south - m.north) / m.dy));
    CPLAddXMLAttributeAndValue(root.get(), "rasterXSize", std::to_string(width).c_str());
    CPLAddXMLAttributeAndValue(root.get(), "rasterYSize", std::to_string(height).c_str());
    if (const auto& srs = files.front()->srs) {
        char* wkt = nullptr;
        srs->exportToWkt(&wkt);
        CPLXMLNode* node = CPLCreateXMLElementAndValue(root.get(), "SRS", wkt ? wkt : "");
        CPLFree(wkt);
        std::string mapping;
        for (int axis : srs->GetDataAxisToSRSAxisMapping()) {
            mapping += mapping.empty() ? "" : ",";
            mapping += std::to_string(axis);
        }
        CPLAddXMLAttributeAndValue(node, "dataAxisToSRSAxisMapping", mapping.c_str());
    }
    const std::string transform =
        number(m.west) + ", " + number(m.dx) + ", 0, " + number(m.north) + ", 0, " + number(m.dy);
    CPLCreateXMLElementAndValue(root.get(), "GeoTransform", transform.c_str());
    CPLXMLNode* band = CPLCreateXMLNode(root.get(), CXT_Element, "VRTRasterBand");
    CPLAddXMLAttributeAndValue(
        band, "dataType", GDALGetDataTypeName(same_scale ? type : GDT_Float64));
    CPLAddXMLAttributeAndValue(band, "band", "1");
    CPLCreateXMLElementAndValue(band, "NoDataValue", number(nodata).c_str());
    // Its files' scales already turn their units into metres.
    CPLCreateXMLElementAndValue(band, "UnitType", "m");
    const DemInfo& first = files.front()->info;
    if (same_scale && (first.scale != 1.0 || first.offset != 0.0)) {
        CPLCreateXMLElementAndValue(band, "Offset", number(first.offset).c_str());
        CPLCreateXMLElementAndValue(band, "Scale", number(first.scale).c_str());
    }
    // A VRT draws its last source on top: the first file goes last.
    for (auto f = files.rbegin(); f != files.rend(); ++f) {
        add_source(band, **f, m, !same_scale);
    }
    add_overview_list(root.get(), files);
    char* text = CPLSerializeXMLTree(root.get());
    std::string out = text ? text : "";
    CPLFree(text);
    return out;
}

bool shares_scale(const std::vector<const FileScan*>& files) {
    return std::all_of(files.begin(), files.end(), [&](const FileScan* f) {
        return f->info.scale == files.front()->info.scale &&
               f->info.offset == files.front()->info.offset;
    });
}

} // namespace tb::tiler
