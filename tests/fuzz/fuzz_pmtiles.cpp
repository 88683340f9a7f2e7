// libFuzzer harness: any bytes as a PMTiles archive, opened with pmtiles::Reader (what
// `serve --store OUT.pmtiles` reads) and walked: every addressed tile looked up and its bytes
// read. A damaged archive must be refused with a tb::Error (InputError or IoError); a crash, an
// out-of-bounds read, another exception or a sanitizer report is a finding.
#include "core/error.hpp"
#include "tiler/log.hpp"
#include "tiler/stores/pmtiles_format.hpp"

#include <cstdint>
#include <cstdlib>
#include <string>

namespace {

using namespace tb::tiler;

// Reads like the store's file reader: exactly `length` bytes or IoError, never past the end.
std::string read_at(const std::string& bytes, std::uint64_t offset, std::uint64_t length) {
    if (offset > bytes.size() || length > bytes.size() - offset) {
        throw tb::IoError("fuzz.pmtiles: read past the end");
    }
    return bytes.substr(offset, length);
}

struct Enough {}; // thrown to end a walk after enough lookups

void walk(const std::string& bytes) {
    const pmtiles::Reader reader(
        "fuzz.pmtiles", bytes.size(), [&](std::uint64_t offset, std::uint64_t length) {
            return read_at(bytes, offset, length);
        });
    int visited = 0;
    reader.for_each_entry([&](std::uint64_t id, std::uint64_t offset, std::uint32_t length) {
        if (offset + length > reader.header().data_length) {
            std::abort(); // the directory parser lets an entry point past the tile data
        }
        if (++visited > 64) {
            throw Enough{}; // runs may address billions of tiles
        }
        // A damaged archive's leaves may disagree with its root, so the lookup may find
        // another tile or none; it must still stay inside the tile data.
        if (const auto tile_id = pmtiles::tile_of(id)) {
            const auto tile = reader.tile(*tile_id);
            if (tile && tile->size() > reader.header().data_length) {
                std::abort();
            }
        }
    });
}

} // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
    tb::log::set_level(tb::log::Level::Off);
    return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    try {
        walk(std::string(reinterpret_cast<const char*>(data), size));
    } catch (const tb::Error&) {
        // refused: what a damaged archive must get
    } catch (const Enough&) {
    }
    return 0;
}
