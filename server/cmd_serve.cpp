// terrabound serve: the HTTP server. Until the server issue lands this answers /health only.
#include "core/error.hpp"
#include "server/commands.hpp"
#include "tiler/gdal_source.hpp"
#include "tiler/log.hpp"

#include <httplib.h>

#include <csignal>

namespace tb::cli {
namespace {

httplib::Server* g_server = nullptr;

void on_signal(int) {
    if (g_server) {
        g_server->stop();
    }
}

int run(const Args& args) {
    const std::string host = args.get("host").value_or("127.0.0.1");
    const long long port = args.get_int("port", 8080);
    if (port < 1 || port > 65535) {
        throw InputError("--port: expected 1..65535, got " + std::to_string(port));
    }
    for (const auto& dem : args.positional) {
        tiler::inspect_dem(dem);  // fail early on a bad DEM
    }
    httplib::Server server;
    server.set_exception_handler([](const httplib::Request&, httplib::Response& res,
                                    std::exception_ptr) {
        res.status = 500;
        res.set_content("{\"error\":\"internal error\"}", "application/json");
    });
    server.Get("/health", [](const httplib::Request&, httplib::Response& res) {
        res.set_content("{\"status\":\"ok\"}\n", "application/json");
    });
    g_server = &server;
    std::signal(SIGINT, on_signal);
    std::signal(SIGTERM, on_signal);
    if (!server.bind_to_port(host, static_cast<int>(port))) {
        throw IoError("cannot listen on " + host + ":" + std::to_string(port) +
                      "; is another server using the port? pick one with --port");
    }
    log::info("serving http://" + host + ":" + std::to_string(port) + "/");
    server.listen_after_bind();
    log::info("stopped");
    return 0;
}

}  // namespace

const Command& serve_command() {
    static const Command command{
        {"serve",
         "[CONFIG.json | DEM...] [--host H] [--port P]",
         "Serve terrain tiles over HTTP.",
         {{"host", "HOST", "address to listen on (default 127.0.0.1)"},
          {"port", "PORT", "port to listen on (default 8080)"}},
         ""},
        run};
    return command;
}

}  // namespace tb::cli
