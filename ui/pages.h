#pragma once
/// The wizard's pages. Each reads what the store holds when it is shown.

#include <QWizardPage>
#include <Eigen/Core>
#include <vector>

#include "store/audit_chain.h"
#include "store/records.h"
#include "ui/wizard.h"

class QLabel;
class QLineEdit;
class QListWidget;
class QPlainTextEdit;
class QProgressBar;
class QPushButton;
class QTableWidget;
class QComboBox;

namespace arpos::ui {

class ModelView;

class CasePage : public QWizardPage {
  Q_OBJECT
 public:
  CasePage(WizardState* state, QWidget* parent = nullptr);
  void initializePage() override;
  bool validatePage() override;

 private:
  void RunCheck();
  void RefreshStore();
  WizardState* state_;
  QLineEdit* store_edit_;
  QLineEdit* case_edit_;
  QListWidget* problems_;
  QPlainTextEdit* store_summary_;
  QLabel* status_;
};

class PlanningPage : public QWizardPage {
  Q_OBJECT
 public:
  PlanningPage(WizardState* state, QWidget* parent = nullptr);
  void initializePage() override;

 private:
  void ImportCase();
  void ShowLatestPlan();
  void ShowRoomMap(PlanId plan);  ///< the plan's newest room map in the view and the label
  WizardState* state_;
  ModelView* model_view_;
  QLabel* plan_label_;
  QPushButton* import_button_;
  QProgressBar* progress_;
};

class SessionPage : public QWizardPage {
  Q_OBJECT
 public:
  SessionPage(WizardState* state, QWidget* parent = nullptr);
  void initializePage() override;

 private:
  void ListSessions();
  void ShowSession(int row);
  void RunSessionStage();
  void AlignFromPicks();
  void ShowPicks();
  WizardState* state_;
  QTableWidget* sessions_;
  ModelView* model_view_;
  QLabel* details_;
  QLabel* stages_;
  QPushButton* run_button_;
  QProgressBar* progress_;
  // Manual alignment: Shift+click pairs a point on the model (red or blue)
  // with one on the reconstruction (grey), in order.
  QLabel* picks_label_;
  QPushButton* align_button_;
  QPushButton* clear_picks_button_;
  long long shown_reconstruction_ = 0;
  std::vector<Eigen::Vector3d> model_picks_, reconstruction_picks_;
};

class AuditPage : public QWizardPage {
  Q_OBJECT
 public:
  AuditPage(WizardState* state, QWidget* parent = nullptr);
  void initializePage() override;

 private:
  void ExportReport();
  /// Verifies the audit log (store/audit_chain.h), shows the outcome in
  /// green or red above the table, and returns it.
  AuditVerification Verify();
  WizardState* state_;
  QLabel* verification_;
  QTableWidget* table_;
};

}  // namespace arpos::ui
