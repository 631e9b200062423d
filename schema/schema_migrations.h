#pragma once
/// The store's schema migrations, embedded at build time from schema/NNNN_*.sql
/// (see schema/CMakeLists.txt). Applied in order by src/store/migrator.h; the
/// migration with `version` v brings a store from user_version v-1 to v.

#include <vector>

namespace arpos {

struct SchemaMigration {
  int version;            ///< 1, 2, 3, ... (the NNNN of the file name)
  const char* file_name;  ///< e.g. "0001_initial.sql", for messages
  const char* sql;        ///< the file's contents, statements separated by ';'
};

/// All migrations in version order; entry i has version i + 1. Thread-safe.
const std::vector<SchemaMigration>& SchemaMigrations();

}  // namespace arpos
