// libFuzzer harness: any bytes as a config file through config::parse_config. Bad configs must
// come back as one InputError listing the problems; any other exception, a crash or a
// sanitizer report is a finding.
#include "config/config.hpp"
#include "core/error.hpp"
#include "tests/server/server_fixture.hpp"
#include "tiler/log.hpp"

#include <cstdint>
#include <cstdlib>

namespace {

// A directory with a small DEM, hills.asc, that seed configs name as their source.
tb::test::TempDir* dir = nullptr;

} // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
    tb::log::set_level(tb::log::Level::Off);
    dir = new tb::test::TempDir;
    tb::test::write_dem(*dir / "hills.asc", 17);
    return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
    const std::string text(reinterpret_cast<const char*>(data), size);
    try {
        const auto config = tb::config::parse_config(text, *dir / "fuzz.json");
        if (config.layers.empty()) {
            std::abort(); // a valid config has at least one layer
        }
        for (const auto& layer : config.layers) {
            if (!tb::config::is_valid_layer_name(layer.options.name) || layer.formats.empty()) {
                std::abort();
            }
        }
    } catch (const tb::InputError& e) {
        if (std::string(e.what()).empty()) {
            std::abort();
        }
    }
    return 0;
}
