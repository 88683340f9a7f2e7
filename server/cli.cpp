#include "server/cli.hpp"

#include "core/error.hpp"

#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <sstream>

namespace tb::cli {

std::optional<std::string> Args::get(const std::string& name) const {
    auto it = values.find(name);
    if (it == values.end()) {
        return std::nullopt;
    }
    return it->second;
}

double Args::get_double(const std::string& name, double fallback) const {
    auto v = get(name);
    return v ? to_double(*v, "--" + name) : fallback;
}

long long Args::get_int(const std::string& name, long long fallback) const {
    auto v = get(name);
    return v ? to_int(*v, "--" + name) : fallback;
}

double to_double(const std::string& text, const std::string& what) {
    errno = 0;
    char* end = nullptr;
    const double v = std::strtod(text.c_str(), &end);
    if (text.empty() || end != text.c_str() + text.size() || errno == ERANGE || !std::isfinite(v)) {
        throw InputError(what + ": expected a number, got '" + text + "'");
    }
    return v;
}

long long to_int(const std::string& text, const std::string& what) {
    errno = 0;
    char* end = nullptr;
    const long long v = std::strtoll(text.c_str(), &end, 10);
    if (text.empty() || end != text.c_str() + text.size() || errno == ERANGE) {
        throw InputError(what + ": expected a whole number, got '" + text + "'");
    }
    return v;
}

std::string extension_of(const std::string& path) {
    const auto slash = path.find_last_of('/');
    const auto dot = path.find_last_of('.');
    if (dot == std::string::npos || (slash != std::string::npos && dot < slash)) {
        return "";
    }
    return path.substr(dot + 1);
}

Args parse(const CommandSpec& spec, const std::vector<std::string>& argv) {
    Args args;
    for (std::size_t i = 0; i < argv.size(); ++i) {
        const std::string& word = argv[i];
        if (word == "-h" || word == "--help") {
            args.help = true;
            continue;
        }
        if (word.size() < 2 || word[0] != '-' || word == "-") {
            args.positional.push_back(word);
            continue;
        }
        std::string name = word.substr(word[1] == '-' ? 2 : 1);
        std::optional<std::string> inline_value;
        if (auto eq = name.find('='); eq != std::string::npos) {
            inline_value = name.substr(eq + 1);
            name = name.substr(0, eq);
        }
        const OptionSpec* option = nullptr;
        for (const auto& o : spec.options) {
            if (o.name == name) {
                option = &o;
            }
        }
        if (!option) {
            throw InputError(spec.name + ": unknown option '" + word + "'; see 'terrabound " +
                             spec.name + " --help'");
        }
        if (option->value.empty()) {
            if (inline_value) {
                throw InputError(spec.name + ": --" + name + " takes no value");
            }
            args.flags.insert(name);
            continue;
        }
        if (inline_value) {
            args.values[name] = *inline_value;
        } else if (i + 1 < argv.size()) {
            args.values[name] = argv[++i];
        } else {
            throw InputError(spec.name + ": --" + name + " needs a value (" + option->value + ")");
        }
    }
    return args;
}

std::string help_text(const CommandSpec& spec) {
    std::ostringstream out;
    out << "usage: terrabound " << spec.name << " " << spec.usage << "\n\n" << spec.summary << "\n";
    if (!spec.options.empty()) {
        out << "\noptions:\n";
        for (const auto& o : spec.options) {
            std::string left = (o.name.size() == 1 ? "-" : "--") + o.name;
            if (!o.value.empty()) {
                left += " " + o.value;
            }
            out << "  " << left;
            out << std::string(left.size() < 22 ? 22 - left.size() : 1, ' ') << o.help << "\n";
        }
        out << "  -h, --help            show this help\n";
    }
    if (!spec.details.empty()) {
        out << "\n" << spec.details << "\n";
    }
    return out.str();
}

} // namespace tb::cli
