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
class QCheckBox;

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
  void RoleChanged();
  WizardState* state_;
  QLineEdit* user_edit_;
  QComboBox* role_combo_;
  QLabel* role_help_;
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
  void ApproveShownPlan();
  void ShowLatestPlan();
  void ShowRoomMap(PlanId plan);  ///< the plan's newest room map in the view and the label
  void UpdateButtons();
  WizardState* state_;
  ModelView* model_view_;
  QLabel* plan_label_;
  QLabel* approval_label_;
  QPushButton* import_button_;
  QPushButton* approve_button_;
  QPushButton* cancel_button_;
  bool running_here_ = false;  ///< this page started the worker's job (its progress is ours)
  long long shown_plan_ = 0;
  bool shown_plan_approvable_ = false;
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
  void EndShownSession(bool completed);
  void UpdateButtons();
  WizardState* state_;
  QTableWidget* sessions_;
  QCheckBox* unapproved_box_;
  QPushButton* complete_button_;
  QPushButton* abort_button_;
  QPushButton* cancel_button_;
  bool running_here_ = false;
  long long shown_session_ = 0;
  bool shown_session_open_ = false;
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
  std::vector<Eigen::Vector3d> model_picks_room_, reconstruction_picks_room_;  ///< where they are drawn
  QString pick_note_;  ///< what the last click that did not count hit
  void ClearPicks();
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
