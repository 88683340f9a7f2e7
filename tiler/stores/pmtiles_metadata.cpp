// PMTiles metadata JSON: written with TileJSON's keys plus a "terrabound" object, read back by a
// small JSON parser (the tiler has no JSON library: config/ alone uses one). The parser accepts
// any JSON an archive from another writer may hold, with nesting limited to 32 levels.
#include "core/error.hpp"
#include "tiler/json_number.hpp"
#include "tiler/stores/pmtiles_format.hpp"

#include <vector>

namespace tb::tiler::pmtiles {
namespace {

struct Json {
    enum class Kind { Null, Bool, Number, String, Array, Object } kind = Kind::Null;
    std::string text; // a string's bytes
    // An object's members as two parallel vectors: a vector of pair<string, Json> would need
    // Json complete inside its own definition.
    std::vector<std::string> keys;
    std::vector<Json> values;
    std::vector<Json> items;
};

const Json* member(const Json& object, const std::string& key) {
    for (std::size_t i = 0; i < object.keys.size(); ++i) {
        if (object.keys[i] == key) {
            return &object.values[i];
        }
    }
    return nullptr;
}

std::string string_at(const Json& object, const std::string& key) {
    const Json* v = member(object, key);
    return v && v->kind == Json::Kind::String ? v->text : std::string();
}

class Parser {
public:
    Parser(std::string_view s, const std::string& name) : s_(s), name_(name) {}

    Json document() {
        Json v = value(0);
        skip_space();
        if (at_ != s_.size()) {
            fail("text after the JSON value");
        }
        return v;
    }

private:
    [[noreturn]] void fail(const std::string& what) const {
        throw InputError(name_ + ": the metadata is not JSON (" + what + " at byte " +
                         std::to_string(at_) + "); the file is damaged");
    }
    void skip_space() {
        while (at_ < s_.size() &&
               (s_[at_] == ' ' || s_[at_] == '\n' || s_[at_] == '\r' || s_[at_] == '\t')) {
            ++at_;
        }
    }
    char peek() {
        skip_space();
        if (at_ >= s_.size()) {
            fail("unexpected end");
        }
        return s_[at_];
    }
    void expect(char c) {
        if (peek() != c) {
            fail(std::string("expected '") + c + "'");
        }
        ++at_;
    }
    bool literal(std::string_view word) {
        if (s_.substr(at_, word.size()) == word) {
            at_ += word.size();
            return true;
        }
        return false;
    }

    Json value(int depth) {
        if (depth > 32) {
            fail("nesting deeper than 32 levels");
        }
        Json v;
        const char c = peek();
        if (c == '{') {
            v.kind = Json::Kind::Object;
            ++at_;
            if (peek() == '}') {
                ++at_;
                return v;
            }
            do {
                if (peek() != '"') {
                    fail("expected a member name");
                }
                std::string key = string();
                expect(':');
                v.keys.push_back(std::move(key));
                v.values.push_back(value(depth + 1));
            } while (peek() == ',' && ++at_);
            expect('}');
        } else if (c == '[') {
            v.kind = Json::Kind::Array;
            ++at_;
            if (peek() == ']') {
                ++at_;
                return v;
            }
            do {
                v.items.push_back(value(depth + 1));
            } while (peek() == ',' && ++at_);
            expect(']');
        } else if (c == '"') {
            v.kind = Json::Kind::String;
            v.text = string();
        } else if (literal("true") || literal("false")) {
            v.kind = Json::Kind::Bool;
        } else if (literal("null")) {
            v.kind = Json::Kind::Null;
        } else {
            number();
            v.kind = Json::Kind::Number;
        }
        return v;
    }

    void number() {
        const std::size_t start = at_;
        while (at_ < s_.size() &&
               std::string_view("+-0123456789.eE").find(s_[at_]) != std::string_view::npos) {
            ++at_;
        }
        if (at_ == start) {
            fail("unexpected character");
        }
    }

    unsigned hex4() {
        if (at_ + 4 > s_.size()) {
            fail("a cut \\u escape");
        }
        unsigned v = 0;
        for (int i = 0; i < 4; ++i) {
            const char h = s_[at_++];
            v <<= 4;
            if (h >= '0' && h <= '9') {
                v |= static_cast<unsigned>(h - '0');
            } else if (h >= 'a' && h <= 'f') {
                v |= static_cast<unsigned>(h - 'a' + 10);
            } else if (h >= 'A' && h <= 'F') {
                v |= static_cast<unsigned>(h - 'A' + 10);
            } else {
                fail("a bad \\u escape");
            }
        }
        return v;
    }

    // \u00XX comes back as the byte XX (json_string writes control bytes so); larger code
    // points as UTF-8, surrogate pairs joined.
    void append_code_point(std::string& out, unsigned cp) {
        if (cp >= 0xd800 && cp < 0xdc00 && s_.substr(at_, 2) == "\\u") {
            at_ += 2;
            const unsigned low = hex4();
            cp = 0x10000 + ((cp - 0xd800) << 10) + (low - 0xdc00);
        }
        if (cp < 0x100) {
            out += static_cast<char>(cp);
        } else if (cp < 0x800) {
            out += static_cast<char>(0xc0 | (cp >> 6));
            out += static_cast<char>(0x80 | (cp & 0x3f));
        } else if (cp < 0x10000) {
            out += static_cast<char>(0xe0 | (cp >> 12));
            out += static_cast<char>(0x80 | ((cp >> 6) & 0x3f));
            out += static_cast<char>(0x80 | (cp & 0x3f));
        } else {
            out += static_cast<char>(0xf0 | ((cp >> 18) & 0x07));
            out += static_cast<char>(0x80 | ((cp >> 12) & 0x3f));
            out += static_cast<char>(0x80 | ((cp >> 6) & 0x3f));
            out += static_cast<char>(0x80 | (cp & 0x3f));
        }
    }

    std::string string() {
        ++at_; // the opening quote
        std::string out;
        for (;;) {
            if (at_ >= s_.size()) {
                fail("an unterminated string");
            }
            const char c = s_[at_++];
            if (c == '"') {
                return out;
            }
            if (c != '\\') {
                out += c;
                continue;
            }
            if (at_ >= s_.size()) {
                fail("an unterminated string");
            }
            const char e = s_[at_++];
            switch (e) {
            case '"':
            case '\\':
            case '/':
                out += e;
                break;
            case 'b':
                out += '\b';
                break;
            case 'f':
                out += '\f';
                break;
            case 'n':
                out += '\n';
                break;
            case 'r':
                out += '\r';
                break;
            case 't':
                out += '\t';
                break;
            case 'u':
                append_code_point(out, hex4());
                break;
            default:
                fail("a bad escape");
            }
        }
    }

    std::string_view s_;
    const std::string& name_;
    std::size_t at_ = 0;
};

double degrees(std::int32_t v) {
    return v / 1e7;
}

} // namespace

std::string metadata_json(const ArchiveContent& c, const Header& h) {
    std::string out =
        "{\"name\":" + json_string(c.layer) + ",\"format\":\"png\"" +
        ",\"type\":\"baselayer\",\"encoding\":" + json_string(c.encoding) + ",\"description\":" +
        json_string("Raster DEM tiles of layer " + c.layer + " (" + c.encoding +
                    " encoding, heights in metres) made by Terrabound") +
        ",\"minzoom\":" + std::to_string(h.min_zoom) +
        ",\"maxzoom\":" + std::to_string(h.max_zoom) + ",\"bounds\":[" +
        json_number(degrees(h.min_lon_e7)) + "," + json_number(degrees(h.min_lat_e7)) + "," +
        json_number(degrees(h.max_lon_e7)) + "," + json_number(degrees(h.max_lat_e7)) +
        "],\"center\":[" + json_number(degrees(h.center_lon_e7)) + "," +
        json_number(degrees(h.center_lat_e7)) + "," + std::to_string(h.center_zoom) + "]";
    out += ",\"terrabound\":{\"layer\":" + json_string(c.layer) +
           ",\"encoding\":" + json_string(c.encoding) + ",\"documents\":{";
    bool first = true;
    for (const auto& [name, bytes] : c.documents) {
        if (!first) {
            out += ',';
        }
        out += json_string(name) + ":" + json_string(bytes);
        first = false;
    }
    return out + "}}}";
}

ArchiveContent parse_metadata(std::string_view json, const std::string& name) {
    const Json doc = Parser(json, name).document();
    if (doc.kind != Json::Kind::Object) {
        throw InputError(name + ": the metadata is not a JSON object; the file is damaged");
    }
    ArchiveContent c;
    const Json* ours = member(doc, "terrabound");
    if (ours && ours->kind == Json::Kind::Object) {
        c.layer = string_at(*ours, "layer");
        c.encoding = string_at(*ours, "encoding");
        if (const Json* docs = member(*ours, "documents")) {
            for (std::size_t i = 0; i < docs->keys.size(); ++i) {
                if (docs->values[i].kind == Json::Kind::String) {
                    c.documents[docs->keys[i]] = docs->values[i].text;
                }
            }
        }
    } else {
        c.layer = string_at(doc, "name");
        c.encoding = string_at(doc, "encoding");
    }
    return c;
}

} // namespace tb::tiler::pmtiles
