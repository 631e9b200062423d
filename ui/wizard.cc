#include "ui/wizard.h"

#include <QMessageBox>

#include "store/sqlite_database.h"
#include "ui/pages.h"
#include "ui/tracking_page.h"
#include "ui/worker.h"

namespace arpos::ui {

std::string WizardState::OpenStore() {
  try {
    database.reset();
    database = SqliteDatabase::Open(options.store_path);
    return "";
  } catch (const std::exception& e) {
    return e.what();
  }
}

ArposWizard::ArposWizard(WizardSettings wizard_options, QWidget* parent)
    : QWizard(parent), state_(std::make_unique<WizardState>()) {
  state_->options = std::move(wizard_options);
  state_->worker = new Worker(this);
  setWindowTitle(tr("ARPos: patient positioning"));
  setWizardStyle(QWizard::ModernStyle);
  setOption(QWizard::NoBackButtonOnStartPage);
  setOption(QWizard::HaveHelpButton, false);
  setPage(kCasePage, new CasePage(state_.get(), this));
  setPage(kPlanningPage, new PlanningPage(state_.get(), this));
  setPage(kSessionPage, new SessionPage(state_.get(), this));
  setPage(kTrackingPage, new TrackingPage(state_.get(), this));
  setPage(kAuditPage, new AuditPage(state_.get(), this));
  resize(1100, 800);
}

ArposWizard::~ArposWizard() = default;

void ArposWizard::reject() {
  if (state_->worker->busy()) {
    const auto answer = QMessageBox::question(
        this, tr("A step is running"),
        tr("A step is still running. Stop it and close ARPos?\n\nWhat it has stored so far stays stored; "
           "the step itself stores nothing."),
        QMessageBox::Yes | QMessageBox::No, QMessageBox::No);
    if (answer != QMessageBox::Yes) return;
    state_->worker->Cancel();
  }
  QWizard::reject();
}

}  // namespace arpos::ui
