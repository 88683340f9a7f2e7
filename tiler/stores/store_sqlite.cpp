// The SQLite store: one file, WAL journal, so one writer and many readers (also from other
// processes on the same machine) work at once.
//   tiles(layer, format, eps_level, z, x, y, data, crc)  PRIMARY KEY(layer, format, eps_level, z,
//                                                         x, y)
//   documents(layer, name, data, crc)                    PRIMARY KEY(layer, name)
//   meta(name, value)                                    schema version and writer
// crc is the CRC-32 of data (tiler/stores/checksum.hpp). A row whose data does not match it is
// damaged: it reads as missing, with a warning, and is made again. Schema version 1 files (no
// crc column) are migrated when opened, in one transaction, taking their data as it is then.
// Each put is one transaction and put_batch is one transaction for the whole batch, so a crash
// leaves every row whole or absent. One connection serves all threads, behind a mutex, with
// its statements prepared once.
#include "core/error.hpp"
#include "tiler/log.hpp"
#include "tiler/stores/checksum.hpp"
#include "tiler/stores/sqlite_db.hpp"
#include "tiler/stores/store.hpp"

#include <filesystem>
#include <memory>
#include <mutex>
#include <sqlite3.h>
#include <string>

#ifndef TB_VERSION
#define TB_VERSION "0.0.0"
#endif

namespace tb::tiler {
namespace {

constexpr int kSchemaVersion = 2;
constexpr int kBusyTimeoutMs = 30000;

struct DbClose {
    void operator()(sqlite3* db) const { sqlite3_close_v2(db); }
};
struct StmtFinalize {
    void operator()(sqlite3_stmt* s) const { sqlite3_finalize(s); }
};
using Db = std::unique_ptr<sqlite3, DbClose>;
using Stmt = std::unique_ptr<sqlite3_stmt, StmtFinalize>;

// Resets a statement however the scope is left, so the next use starts clean.
struct Reset {
    sqlite3_stmt* s;
    ~Reset() {
        sqlite3_reset(s);
        sqlite3_clear_bindings(s);
    }
};

class SqliteStore final : public TileStore {
public:
    explicit SqliteStore(std::string path) : path_(std::move(path)) {
        std::error_code ec;
        const auto parent = std::filesystem::path(path_).parent_path();
        if (!parent.empty() && !std::filesystem::exists(parent, ec)) {
            throw IoError(path_ + ": its parent directory " + parent.string() +
                          " does not exist; create it first or choose another output path");
        }
        sqlite3* raw = nullptr;
        const int rc =
            sqlite3_open_v2(path_.c_str(),
                            &raw,
                            SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE | SQLITE_OPEN_NOMUTEX,
                            nullptr);
        db_.reset(raw);
        check(rc, "open");
        sqlite3_extended_result_codes(db_.get(), 1);
        sqlite3_busy_timeout(db_.get(), kBusyTimeoutMs);
        exec("PRAGMA journal_mode=WAL", "switch to WAL");
        exec("PRAGMA synchronous=NORMAL", "set synchronous");
        exec("BEGIN IMMEDIATE", "create tables");
        try {
            exec("CREATE TABLE IF NOT EXISTS meta(name TEXT PRIMARY KEY, value TEXT NOT NULL);"
                 "CREATE TABLE IF NOT EXISTS tiles(layer TEXT NOT NULL, format TEXT NOT NULL,"
                 " eps_level INTEGER NOT NULL, z INTEGER NOT NULL, x INTEGER NOT NULL,"
                 " y INTEGER NOT NULL, data BLOB NOT NULL, crc INTEGER NOT NULL,"
                 " PRIMARY KEY(layer, format, eps_level, z, x, y));"
                 "CREATE TABLE IF NOT EXISTS documents(layer TEXT NOT NULL, name TEXT NOT NULL,"
                 " data BLOB NOT NULL, crc INTEGER NOT NULL, PRIMARY KEY(layer, name));"
                 "INSERT OR IGNORE INTO meta VALUES('schema_version', '" +
                     std::to_string(kSchemaVersion) +
                     "');"
                     "INSERT OR IGNORE INTO meta VALUES('created_by', 'terrabound " TB_VERSION
                     "');",
                 "create tables");
            exec("COMMIT", "create tables");
        } catch (...) {
            sqlite3_exec(db_.get(), "ROLLBACK", nullptr, nullptr, nullptr);
            throw;
        }
        check_schema_version();
        get_ = prepare("SELECT data, crc FROM tiles WHERE layer=?1 AND format=?2 AND eps_level=?3"
                       " AND z=?4 AND x=?5 AND y=?6");
        put_ = prepare("INSERT OR REPLACE INTO tiles(layer, format, eps_level, z, x, y, data, crc)"
                       " VALUES(?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8)");
        get_doc_ = prepare("SELECT data, crc FROM documents WHERE layer=?1 AND name=?2");
        put_doc_ = prepare(
            "INSERT OR REPLACE INTO documents(layer, name, data, crc) VALUES(?1, ?2, ?3, ?4)");
        has_layer_ = prepare("SELECT EXISTS(SELECT 1 FROM tiles WHERE layer=?1)"
                             " OR EXISTS(SELECT 1 FROM documents WHERE layer=?1)");
    }

    std::optional<std::string> get(const TileKey& key) const override {
        validate_key(key);
        std::lock_guard lock(mutex_);
        Reset reset{get_.get()};
        bind_key(get_.get(), key);
        return fetch_verified(get_.get(), "read a tile", [&] { return describe_key(key); });
    }

    // A tile counts only when it is whole: --resume re-makes damaged ones.
    bool contains(const TileKey& key) const override { return get(key).has_value(); }

    void put(const TileKey& key, std::string_view bytes) override {
        validate_key(key);
        std::lock_guard lock(mutex_);
        put_locked(key, bytes); // autocommit: one transaction
    }

    void put_batch(std::span<const StoredTile> tiles) override {
        for (const auto& t : tiles) {
            validate_key(t.key);
        }
        std::lock_guard lock(mutex_);
        exec("BEGIN IMMEDIATE", "start a transaction");
        try {
            for (const auto& t : tiles) {
                put_locked(t.key, t.bytes);
            }
            exec("COMMIT", "commit tiles");
        } catch (...) {
            sqlite3_exec(db_.get(), "ROLLBACK", nullptr, nullptr, nullptr);
            throw;
        }
    }

    std::optional<std::string> get_document(const std::string& layer,
                                            const std::string& name) const override {
        validate_layer_name(layer);
        validate_document_name(name);
        std::lock_guard lock(mutex_);
        Reset reset{get_doc_.get()};
        bind_text(get_doc_.get(), 1, layer);
        bind_text(get_doc_.get(), 2, name);
        return fetch_verified(
            get_doc_.get(), "read a document", [&] { return "document " + layer + "/" + name; });
    }

    void put_document(const std::string& layer,
                      const std::string& name,
                      std::string_view bytes) override {
        validate_layer_name(layer);
        validate_document_name(name);
        std::lock_guard lock(mutex_);
        Reset reset{put_doc_.get()};
        bind_text(put_doc_.get(), 1, layer);
        bind_text(put_doc_.get(), 2, name);
        bind_blob(put_doc_.get(), 3, bytes);
        sqlite3_bind_int64(put_doc_.get(), 4, store_checksum(bytes));
        step(put_doc_.get(), "write a document");
    }

    void remove(const TileKey& key) override {
        validate_key(key);
        std::lock_guard lock(mutex_);
        Stmt s = prepare("DELETE FROM tiles WHERE layer=?1 AND format=?2 AND eps_level=?3"
                         " AND z=?4 AND x=?5 AND y=?6");
        bind_key(s.get(), key);
        step(s.get(), "remove a tile");
    }

    void remove_document(const std::string& layer, const std::string& name) override {
        validate_layer_name(layer);
        validate_document_name(name);
        std::lock_guard lock(mutex_);
        Stmt s = prepare("DELETE FROM documents WHERE layer=?1 AND name=?2");
        bind_text(s.get(), 1, layer);
        bind_text(s.get(), 2, name);
        step(s.get(), "remove a document");
    }

    bool has_layer(const std::string& layer) const override {
        validate_layer_name(layer);
        std::lock_guard lock(mutex_);
        Reset reset{has_layer_.get()};
        bind_text(has_layer_.get(), 1, layer);
        step(has_layer_.get(), "look up a layer");
        return sqlite3_column_int(has_layer_.get(), 0) != 0;
    }

    void remove_layer(const std::string& layer) override {
        validate_layer_name(layer);
        std::lock_guard lock(mutex_);
        exec("BEGIN IMMEDIATE", "start a transaction");
        try {
            for (const char* sql :
                 {"DELETE FROM tiles WHERE layer=?1", "DELETE FROM documents WHERE layer=?1"}) {
                Stmt s = prepare(sql);
                bind_text(s.get(), 1, layer);
                step(s.get(), "remove a layer");
            }
            exec("COMMIT", "remove a layer");
        } catch (...) {
            sqlite3_exec(db_.get(), "ROLLBACK", nullptr, nullptr, nullptr);
            throw;
        }
    }

    void clean_up(const std::string& layer) override {
        validate_layer_name(layer); // transactions leave nothing behind
    }

    std::string describe() const override { return "sqlite " + path_; }
    bool written_by_terrabound_only() const override { return true; }

private:
    [[noreturn]] void fail(int rc, const std::string& action) const {
        const char* msg = db_ ? sqlite3_errmsg(db_.get()) : sqlite3_errstr(rc);
        throw IoError(path_ + ": cannot " + action + " (" + msg + "); " + sqlite_advice(rc));
    }

    void check(int rc, const std::string& action) const {
        if (rc != SQLITE_OK) {
            fail(rc, action);
        }
    }

    void exec(const std::string& sql, const std::string& action) const {
        check(sqlite3_exec(db_.get(), sql.c_str(), nullptr, nullptr, nullptr), action);
    }

    Stmt prepare(const char* sql) const {
        sqlite3_stmt* raw = nullptr;
        check(sqlite3_prepare_v3(db_.get(), sql, -1, SQLITE_PREPARE_PERSISTENT, &raw, nullptr),
              "prepare a statement (is this a Terrabound store?)");
        return Stmt(raw);
    }

    int step(sqlite3_stmt* s, const std::string& action) const {
        const int rc = sqlite3_step(s);
        if (rc != SQLITE_ROW && rc != SQLITE_DONE) {
            fail(rc, action);
        }
        return rc;
    }

    static void bind_text(sqlite3_stmt* s, int i, std::string_view text) {
        sqlite3_bind_text64(s, i, text.data(), text.size(), SQLITE_TRANSIENT, SQLITE_UTF8);
    }

    static void bind_blob(sqlite3_stmt* s, int i, std::string_view bytes) {
        if (bytes.empty()) {
            sqlite3_bind_zeroblob(s, i, 0); // a null pointer would bind NULL, not an empty blob
        } else {
            sqlite3_bind_blob64(s, i, bytes.data(), bytes.size(), SQLITE_STATIC);
        }
    }

    static void bind_key(sqlite3_stmt* s, const TileKey& key) {
        bind_text(s, 1, key.layer);
        bind_text(s, 2, format_name(key.format));
        sqlite3_bind_int(s, 3, key.eps_level);
        sqlite3_bind_int(s, 4, key.id.z);
        sqlite3_bind_int64(s, 5, key.id.x);
        sqlite3_bind_int64(s, 6, key.id.y);
    }

    static std::string describe_key(const TileKey& key) {
        return "tile " + key.layer + "/" +
               (key.eps_level >= 0 ? "eps" + std::to_string(key.eps_level) + "/" : "") +
               std::to_string(key.id.z) + "/" + std::to_string(key.id.x) + "/" +
               std::to_string(key.id.y) + "." + extension(key.format);
    }

    // The row's data (column 0) when it matches its checksum (column 1); nullopt when there is
    // no row, and also (with a warning naming `what`) when the data is damaged.
    template <typename What>
    std::optional<std::string>
    fetch_verified(sqlite3_stmt* s, const std::string& action, What what) const {
        if (step(s, action) != SQLITE_ROW) {
            return std::nullopt;
        }
        const void* data = sqlite3_column_blob(s, 0);
        const int size = sqlite3_column_bytes(s, 0);
        std::string bytes =
            size > 0 ? std::string(static_cast<const char*>(data), size) : std::string();
        const bool has_crc = sqlite3_column_type(s, 1) == SQLITE_INTEGER;
        if (!has_crc || sqlite3_column_int64(s, 1) != store_checksum(bytes)) {
            log::warn(path_ + ": " + what() + " is damaged (" + std::to_string(bytes.size()) +
                      " bytes that do not match their checksum); not served, it is made again");
            return std::nullopt;
        }
        return bytes;
    }

    void put_locked(const TileKey& key, std::string_view bytes) {
        Reset reset{put_.get()};
        bind_key(put_.get(), key);
        bind_blob(put_.get(), 7, bytes);
        sqlite3_bind_int64(put_.get(), 8, store_checksum(bytes));
        step(put_.get(), "write a tile");
    }

    // Schema 1 -> 2: adds the crc columns and fills them from the data as it is now.
    void migrate_from_1() {
        exec("BEGIN IMMEDIATE", "migrate the store to schema version 2");
        try {
            check(sqlite3_create_function_v2(db_.get(),
                                             "tb_crc32",
                                             1,
                                             SQLITE_UTF8 | SQLITE_DETERMINISTIC,
                                             nullptr,
                                             &sql_crc32,
                                             nullptr,
                                             nullptr,
                                             nullptr),
                  "migrate the store to schema version 2");
            exec("ALTER TABLE tiles ADD COLUMN crc INTEGER;"
                 "UPDATE tiles SET crc = tb_crc32(data);"
                 "ALTER TABLE documents ADD COLUMN crc INTEGER;"
                 "UPDATE documents SET crc = tb_crc32(data);"
                 "UPDATE meta SET value='2' WHERE name='schema_version';",
                 "migrate the store to schema version 2");
            exec("COMMIT", "migrate the store to schema version 2");
        } catch (...) {
            sqlite3_exec(db_.get(), "ROLLBACK", nullptr, nullptr, nullptr);
            throw;
        }
        log::info(path_ + ": migrated to store schema version 2 (a checksum per tile)");
    }

    static void sql_crc32(sqlite3_context* context, int, sqlite3_value** args) {
        const void* data = sqlite3_value_blob(args[0]);
        const int size = sqlite3_value_bytes(args[0]);
        sqlite3_result_int64(
            context,
            store_checksum(std::string_view(static_cast<const char*>(data), data ? size : 0)));
    }

    void check_schema_version() {
        Stmt s = prepare("SELECT value FROM meta WHERE name='schema_version'");
        if (step(s.get(), "read the schema version") == SQLITE_ROW) {
            const auto* text = sqlite3_column_text(s.get(), 0);
            const std::string version = text ? reinterpret_cast<const char*>(text) : "";
            if (version == "1") {
                s.reset();
                migrate_from_1();
                return;
            }
            if (version != std::to_string(kSchemaVersion)) {
                throw IoError(path_ + ": store schema version " + version +
                              ", this terrabound "
                              "reads version " +
                              std::to_string(kSchemaVersion) +
                              "; rebuild the store or use a matching terrabound");
            }
        }
    }

    std::string path_;
    Db db_;
    mutable std::mutex mutex_;
    Stmt get_, put_, get_doc_, put_doc_, has_layer_;
};

} // namespace

std::unique_ptr<TileStore> open_sqlite_store(const std::string& path) {
    return std::make_unique<SqliteStore>(path);
}

} // namespace tb::tiler
