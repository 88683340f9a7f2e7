#pragma once
// Command-line parsing shared by the subcommands: `--name value`, `--name=value`, flags,
// positionals, and `--help`. Unknown options and missing values are InputErrors.
#include <map>
#include <optional>
#include <set>
#include <string>
#include <vector>

namespace tb::cli {

struct OptionSpec {
    std::string name;  // without the leading "--"
    std::string value; // placeholder shown in help ("E", "PATH"); empty for a flag
    std::string help;
};

struct CommandSpec {
    std::string name;
    std::string usage;   // "INPUT --eps E -o OUT"
    std::string summary; // one line
    std::vector<OptionSpec> options;
    std::string details; // extra help text, may be empty
};

struct Args {
    std::vector<std::string> positional;
    std::map<std::string, std::string> values;
    std::set<std::string> flags;
    bool help = false;

    bool has(const std::string& name) const { return values.count(name) || flags.count(name); }
    std::optional<std::string> get(const std::string& name) const;
    double get_double(const std::string& name, double fallback) const;
    long long get_int(const std::string& name, long long fallback) const;
};

Args parse(const CommandSpec& spec, const std::vector<std::string>& argv);
std::string help_text(const CommandSpec& spec);

// Strict number parsing for user input: the whole string, finite. InputError naming `what`.
double to_double(const std::string& text, const std::string& what);
long long to_int(const std::string& text, const std::string& what);

// The extension of a path's file name without the dot ("out.glb" -> "glb"), or "".
std::string extension_of(const std::string& path);

} // namespace tb::cli
