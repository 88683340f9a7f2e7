// SqliteDb: the containers' SQLite connection and its errors.
#include "tiler/stores/sqlite_db.hpp"

#include "core/error.hpp"

#include <filesystem>

namespace tb::tiler {
namespace {

constexpr int kBusyTimeoutMs = 30000;

} // namespace

std::string sqlite_advice(int code) {
    switch (code & 0xff) {
    case SQLITE_FULL:
        return "the disk is full; free space and try again";
    case SQLITE_NOTADB:
    case SQLITE_CORRUPT:
        return "the file is not an SQLite database or is damaged; move it away or choose another "
               "output path";
    case SQLITE_READONLY:
    case SQLITE_PERM:
    case SQLITE_CANTOPEN:
    case SQLITE_AUTH:
        return "the file cannot be opened for writing; fix its permissions or choose another "
               "output path";
    case SQLITE_BUSY:
    case SQLITE_LOCKED:
        return "another process holds the database locked; stop it or try again later";
    case SQLITE_IOERR:
        return "the disk reported an I/O error; check it and try again";
    default:
        return "check the file, or choose another output path";
    }
}

SqliteDb::SqliteDb(std::string path, bool create) : path_(std::move(path)) {
    std::error_code ec;
    const auto parent = std::filesystem::path(path_).parent_path();
    if (!parent.empty() && !std::filesystem::exists(parent, ec)) {
        throw IoError(path_ + ": its parent directory " + parent.string() +
                      " does not exist; create it first or choose another output path");
    }
    open(SQLITE_OPEN_READWRITE | (create ? SQLITE_OPEN_CREATE : 0));
    try {
        exec("PRAGMA journal_mode=WAL", "switch to WAL");
        exec("PRAGMA synchronous=NORMAL", "set synchronous");
    } catch (...) {
        sqlite3_close_v2(db_);
        throw;
    }
}

SqliteDb::SqliteDb(std::string path, SqliteReadOnly) : path_(std::move(path)) {
    open(SQLITE_OPEN_READONLY);
}

void SqliteDb::open(int flags) {
    const int rc = sqlite3_open_v2(path_.c_str(), &db_, flags | SQLITE_OPEN_NOMUTEX, nullptr);
    if (rc != SQLITE_OK) {
        const std::string msg = db_ ? sqlite3_errmsg(db_) : sqlite3_errstr(rc);
        sqlite3_close_v2(db_);
        db_ = nullptr;
        throw IoError(path_ + ": cannot open (" + msg + "); " + sqlite_advice(rc));
    }
    sqlite3_extended_result_codes(db_, 1);
    sqlite3_busy_timeout(db_, kBusyTimeoutMs);
}

SqliteDb::~SqliteDb() {
    sqlite3_close_v2(db_);
}

void SqliteDb::fail(int rc, const std::string& action) const {
    const char* msg = db_ ? sqlite3_errmsg(db_) : sqlite3_errstr(rc);
    throw IoError(path_ + ": cannot " + action + " (" + msg + "); " + sqlite_advice(rc));
}

void SqliteDb::exec(const std::string& sql, const std::string& action) const {
    const int rc = sqlite3_exec(db_, sql.c_str(), nullptr, nullptr, nullptr);
    if (rc != SQLITE_OK) {
        fail(rc, action);
    }
}

bool SqliteDb::try_exec(const std::string& sql) const {
    return sqlite3_exec(db_, sql.c_str(), nullptr, nullptr, nullptr) == SQLITE_OK;
}

SqliteStmt SqliteDb::prepare(const char* sql) const {
    sqlite3_stmt* raw = nullptr;
    const int rc = sqlite3_prepare_v3(db_, sql, -1, SQLITE_PREPARE_PERSISTENT, &raw, nullptr);
    if (rc != SQLITE_OK) {
        fail(rc, "prepare a statement (is this a Terrabound store?)");
    }
    return SqliteStmt(raw);
}

int SqliteDb::step(sqlite3_stmt* s, const std::string& action) const {
    const int rc = sqlite3_step(s);
    if (rc != SQLITE_ROW && rc != SQLITE_DONE) {
        fail(rc, action);
    }
    return rc;
}

void SqliteDb::transaction(const std::string& action, const std::function<void()>& fn) const {
    exec("BEGIN IMMEDIATE", action);
    try {
        fn();
        exec("COMMIT", action);
    } catch (...) {
        sqlite3_exec(db_, "ROLLBACK", nullptr, nullptr, nullptr);
        throw;
    }
}

void SqliteDb::bind_text(sqlite3_stmt* s, int i, std::string_view text) {
    sqlite3_bind_text64(s, i, text.data(), text.size(), SQLITE_TRANSIENT, SQLITE_UTF8);
}

void SqliteDb::bind_blob(sqlite3_stmt* s, int i, std::string_view bytes) {
    if (bytes.empty()) {
        sqlite3_bind_zeroblob(s, i, 0); // a null pointer would bind NULL, not an empty blob
    } else {
        sqlite3_bind_blob64(s, i, bytes.data(), bytes.size(), SQLITE_STATIC);
    }
}

std::string SqliteDb::column_bytes(sqlite3_stmt* s, int i) {
    const void* data = sqlite3_column_blob(s, i);
    const int size = sqlite3_column_bytes(s, i);
    return size > 0 && data ? std::string(static_cast<const char*>(data), size) : std::string();
}

} // namespace tb::tiler
