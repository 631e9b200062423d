#pragma once
/// The ARPos wizard: one page per workflow stage (case and store, planning,
/// session, tracking, audit). Pages drive the same controllers as the CLI, on
/// a worker thread, and read the session store for what is already done.

#include <QWizard>
#include <memory>
#include <string>

#include "store/roles.h"

namespace arpos {
class Database;
}

namespace arpos::ui {

class Worker;

struct WizardSettings {
  std::string store_path;  ///< session store file
  std::string case_dir;    ///< preselected case folder (may be empty)
  std::string user;        ///< --user / ARPOS_USER (empty: the login name)
  std::string role;        ///< --role / ARPOS_ROLE (empty: chosen on the first page)
  /// Driven by a script (arpos gui --page/--screenshot): no questions that
  /// wait for a person; what they would say goes to the log.
  bool unattended = false;
};

/// State shared by the pages: the open store and the chosen case.
struct WizardState {
  WizardSettings options;
  std::unique_ptr<Database> database;
  Worker* worker = nullptr;
  /// Who works at the wizard: chosen on the first page (store/roles.h). Each
  /// page enables what the role may do; the controllers check it again.
  Operator op;
  /// (Re)opens the store at options.store_path; returns an error or "".
  std::string OpenStore();
};

class ArposWizard : public QWizard {
  Q_OBJECT
 public:
  enum PageId { kCasePage, kPlanningPage, kSessionPage, kTrackingPage, kAuditPage };
  explicit ArposWizard(WizardSettings options, QWidget* parent = nullptr);
  ~ArposWizard() override;
  WizardState& state() { return *state_; }
  /// Escape, Cancel or closing the window: while a step runs, asks first,
  /// then stops the step (it ends at its next check) and closes.
  void reject() override;

 private:
  std::unique_ptr<WizardState> state_;
};

}  // namespace arpos::ui
