#pragma once
/// The wizard's pages. Each reads what the store holds when it is shown.

#include <QWizardPage>
#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <map>
#include <memory>
#include <vector>

#include "geometry/rigid3.h"
#include "geometry/triangle_mesh.h"
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
class QTreeWidget;
class QTreeWidgetItem;

namespace arpos {
struct SessionReport;
}  // namespace arpos

namespace arpos::ui {

class ModelView;
class CorrectionPlot;

/// Colours each vertex of `surface` (room frame) by its distance to `model`
/// at `room_from_model`: green under 2 mm, through yellow (5 mm) to red at
/// 10 mm and beyond; grey past 30 mm (not the patient: couch, clothes).
/// Returns the colours and fills the share of vertices within 2 / 5 mm of
/// those within 30 mm, and their median distance.
std::vector<std::array<std::uint8_t, 3>> DistanceColours(const TriangleMesh& surface, const TriangleMesh& model,
                                                         const Rigid3d& room_from_model, double* within_2mm,
                                                         double* within_5mm, double* median_mm);

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
  /// The room frame's consequence for tracking when it alone keeps every
  /// frame from reading `in` (DescribeRoomFrame); hidden otherwise.
  QLabel* room_frame_label_;
  QString room_frame_warning_;
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

/// The audit page: a tree of patients, plans, sessions and what each
/// session stored (body marker maps, reconstructions, alignments, tracking
/// runs) at the left; the audit entries of the selected node and everything
/// under it in the middle, narrowed by free text, action and age; the
/// selected artefact at the right (3D view, or a run's correction plot and
/// figures).
class AuditPage : public QWizardPage {
  Q_OBJECT
 public:
  AuditPage(WizardState* state, QWidget* parent = nullptr);
  ~AuditPage() override;
  void initializePage() override;
  /// Selects the tree node of `entity` ("session:1", "tracking_run:2", ...;
  /// empty: the whole log). Returns false if the tree has no such node.
  bool SelectEntity(const QString& entity);
  /// Rows shown in the table and entries in the log.
  int ShownEntries() const;
  int TotalEntries() const { return static_cast<int>(entries_.size()); }

 private:
  void ExportReport();
  /// Verifies the audit log (store/audit_chain.h), shows the outcome in
  /// green or red above the table, and returns it.
  AuditVerification Verify();
  void BuildTree();
  void ApplyFilters();
  void ShowDetail(QTreeWidgetItem* item);
  void ShowRun(const SessionReport& report, long long run_id);
  /// The plan's model at its target (blue) and, when given, the
  /// reconstruction coloured by its distance to the model at `alignment`.
  void ShowModels(long long plan_id, long long reconstruction_id, long long alignment_id, QStringList* lines);
  WizardState* state_;
  QLabel* verification_;
  QTreeWidget* tree_;
  QLineEdit* text_filter_;
  QComboBox* action_filter_;
  QComboBox* age_filter_;
  QLabel* count_label_;
  QTableWidget* table_;
  QLabel* detail_title_;
  ModelView* model_view_;
  CorrectionPlot* run_plot_;
  QLabel* detail_text_;
  std::vector<AuditEntry> entries_;
  std::int64_t first_bad_entry_ = 0;
  std::map<long long, std::unique_ptr<SessionReport>> reports_;  ///< by session id
};

}  // namespace arpos::ui
