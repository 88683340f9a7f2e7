// libFuzzer harness: any bytes as a summary file (tiler/summary/summary_file.hpp) read back by
// load_summary. A damaged, cut or foreign file must come back as nullopt (with a warning); a
// summary it accepts must have the shape its size promises. A crash, an exception or a
// sanitizer report is a finding.
#include "tiler/log.hpp"
#include "tiler/stores/checksum.hpp"
#include "tiler/summary/summary_file.hpp"

#include <unistd.h>

#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <string>

namespace {

std::string* path = nullptr;
const std::string kKey = "fuzz key"; // the seeds are written under this key

// Loads `bytes` as a summary file and checks what comes back.
void check(const std::string& bytes) {
    {
        std::ofstream out(*path, std::ios::binary | std::ios::trunc);
        out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
    }
    const auto summary = tb::tiler::load_summary(*path, kKey);
    if (summary) {
        const int finest = summary->finest_level(), coarsest = summary->coarsest_level();
        if (summary->width() < 1 || summary->height() < 1 || coarsest < finest ||
            summary->blocks_across(coarsest) != 1 || summary->blocks_down(coarsest) != 1) {
            std::abort();
        }
        for (int level = finest; level <= coarsest; ++level) {
            const auto last_x = summary->blocks_across(level) - 1;
            const auto last_y = summary->blocks_down(level) - 1;
            if (summary->block(level, last_x, last_y) == nullptr ||
                summary->block(level, last_x + 1, 0) != nullptr) {
                std::abort();
            }
        }
    }
}

} // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
    tb::log::set_level(tb::log::Level::Off);
    path = new std::string("/tmp/fuzz_summary-" + std::to_string(::getpid()) + ".tbsum");
    return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    std::string bytes(reinterpret_cast<const char*>(data), size);
    check(bytes);
    // Again with the checksum made right, so that mutations reach the header and level parsing
    // behind it instead of stopping at the CRC.
    if (bytes.size() >= 4) {
        const std::uint32_t crc =
            tb::tiler::store_checksum(std::string_view(bytes).substr(0, bytes.size() - 4));
        std::memcpy(bytes.data() + bytes.size() - 4, &crc, 4);
        check(bytes);
    }
    return 0;
}
