#pragma once
// One SQLite connection for the single-file containers (MBTiles, and PMTiles' staging file),
// and for reading a store read-only (tiler/pyramid/convert.cpp): statements, transactions and
// SQLite's result codes turned into IoError naming the file, the action and what to do. Not
// thread-safe: callers hold their own mutex.
#include <functional>
#include <memory>
#include <sqlite3.h>
#include <string>
#include <string_view>

namespace tb::tiler {

struct SqliteStmtFinalize {
    void operator()(sqlite3_stmt* s) const { sqlite3_finalize(s); }
};
using SqliteStmt = std::unique_ptr<sqlite3_stmt, SqliteStmtFinalize>;

// Resets a statement however the scope is left, so the next use starts clean.
struct SqliteReset {
    sqlite3_stmt* s;
    ~SqliteReset() {
        sqlite3_reset(s);
        sqlite3_clear_bindings(s);
    }
};

// What to do about an SQLite result code, for the end of an error message.
std::string sqlite_advice(int code);

// Selects SqliteDb's read-only constructor.
struct SqliteReadOnly {};

class SqliteDb {
public:
    // Opens (creating when `create`) the database at `path` in WAL mode. IoError naming the
    // path when its parent directory is missing or SQLite refuses.
    SqliteDb(std::string path, bool create);
    // Opens the existing database at `path` for reading only: the file keeps its journal mode
    // and content. IoError naming the path when SQLite refuses.
    SqliteDb(std::string path, SqliteReadOnly);
    ~SqliteDb();
    SqliteDb(const SqliteDb&) = delete;
    SqliteDb& operator=(const SqliteDb&) = delete;

    void exec(const std::string& sql, const std::string& action) const;
    // Runs `sql`, returning whether SQLite accepted it (for steps that may fail harmlessly).
    bool try_exec(const std::string& sql) const;
    SqliteStmt prepare(const char* sql) const;
    // SQLITE_ROW or SQLITE_DONE; IoError otherwise.
    int step(sqlite3_stmt* s, const std::string& action) const;
    // Runs `fn` in one IMMEDIATE transaction: committed when it returns, rolled back when it
    // throws.
    void transaction(const std::string& action, const std::function<void()>& fn) const;
    [[noreturn]] void fail(int rc, const std::string& action) const;

    static void bind_text(sqlite3_stmt* s, int i, std::string_view text);
    static void bind_blob(sqlite3_stmt* s, int i, std::string_view bytes);
    static std::string column_bytes(sqlite3_stmt* s, int i);

    const std::string& path() const { return path_; }

private:
    void open(int flags);

    std::string path_;
    sqlite3* db_ = nullptr;
};

} // namespace tb::tiler
