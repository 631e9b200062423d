#include "store/database.h"

namespace arpos {

std::int64_t StoreInfo::RowCount(const std::string& table) const {
  for (const auto& [name, count] : table_row_counts) {
    if (name == table) return count;
  }
  return -1;
}

}  // namespace arpos
