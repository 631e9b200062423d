#include "ui/pages.h"

#include <QCheckBox>
#include <QColor>
#include <QInputDialog>
#include <QComboBox>
#include <QFileDialog>
#include <QFormLayout>
#include <QHBoxLayout>
#include <QHeaderView>
#include <QInputDialog>
#include <QLabel>
#include <QLineEdit>
#include <QListWidget>
#include <QMessageBox>
#include <QPlainTextEdit>
#include <QProgressBar>
#include <QPushButton>
#include <QTableWidget>
#include <QTextStream>
#include <QVBoxLayout>
#include <algorithm>
#include <array>
#include <fstream>

#include "controllers/run_case_controller.h"
#include "controllers/session_controller.h"
#include "features/marker_pose.h"
#include "geometry/so3.h"
#include "registration/kdtree.h"
#include "registration/mesh_cloud.h"
#include "report/report_writer.h"
#include "report/session_report.h"
#include "room_map/plan_stage.h"
#include "sensor/case_check.h"
#include "sensor/case_folder.h"
#include "store/database.h"
#include "store/describe.h"
#include "store/lifecycle.h"
#include "store/record_conversions.h"
#include "store/sqlite_database.h"
#include "tracking/tracking_stage.h"
#include "ui/model_view.h"
#include "ui/worker.h"
#include "util/logging.h"
#include "util/string_util.h"

namespace arpos::ui {
namespace {

QString Q(const std::string& s) { return QString::fromStdString(s); }

// Appends a flat quadrilateral (corners in order around it) as two triangles.
void AddQuad(TriangleMesh* mesh, const std::array<Eigen::Vector3d, 4>& corners) {
  const int base = static_cast<int>(mesh->vertices.size());
  for (const auto& c : corners) mesh->vertices.push_back(c.cast<float>());
  mesh->faces.emplace_back(base, base + 1, base + 2);
  mesh->faces.emplace_back(base, base + 2, base + 3);
}

QPushButton* BrowseButton(QWidget* parent, QLineEdit* edit, bool folder) {
  auto* button = new QPushButton(QObject::tr("Browse…"), parent);
  QObject::connect(button, &QPushButton::clicked, parent, [parent, edit, folder] {
    const QString path = folder ? QFileDialog::getExistingDirectory(parent, QObject::tr("Case folder"), edit->text())
                                : QFileDialog::getSaveFileName(parent, QObject::tr("Session store"), edit->text(),
                                                               QObject::tr("SQLite (*.db)"), nullptr,
                                                               QFileDialog::DontConfirmOverwrite);
    if (!path.isEmpty()) edit->setText(path);
  });
  return button;
}

}  // namespace

std::vector<std::array<std::uint8_t, 3>> DistanceColours(const TriangleMesh& surface, const TriangleMesh& model,
                                                         const Rigid3d& room_from_model, double* within_2mm,
                                                         double* within_5mm, double* median_mm) {
  const PointCloud in_room = SampleMeshSurface(model, 0.0015).Transformed(room_from_model);
  const KdTree tree(in_room);
  std::vector<std::array<std::uint8_t, 3>> rgb(surface.vertices.size(), {{150, 150, 150}});
  std::vector<double> near;
  int n2 = 0, n5 = 0;
  for (size_t i = 0; i < surface.vertices.size(); ++i) {
    size_t index = 0;
    double sq = 0;
    const Eigen::Vector3d v = surface.vertices[i].cast<double>();
    if (!tree.Nearest(v, &index, &sq)) continue;
    const double mm = 1000 * std::sqrt(sq);
    if (mm > 30) continue;
    near.push_back(mm);
    n2 += mm < 2;
    n5 += mm < 5;
    const double t = std::clamp(mm / 10.0, 0.0, 1.0);  // 0 green, 0.5 yellow, 1 red
    const double r = t < 0.5 ? 2 * t : 1.0, g = t < 0.5 ? 1.0 : 2 * (1 - t);
    rgb[i] = {{static_cast<std::uint8_t>(40 + 200 * r), static_cast<std::uint8_t>(40 + 170 * g), 50}};
  }
  const double n = std::max<double>(1, near.size());
  *within_2mm = n2 / n;
  *within_5mm = n5 / n;
  std::nth_element(near.begin(), near.begin() + near.size() / 2, near.end());
  *median_mm = near.empty() ? 0 : near[near.size() / 2];
  return rgb;
}

// ---------------------------------------------------------------- case

CasePage::CasePage(WizardState* state, QWidget* parent) : QWizardPage(parent), state_(state) {
  setTitle(tr("Case and session store"));
  setSubTitle(tr("Choose where results are stored and the case folder to work on. "
                 "Check the case before planning."));
  // Who: the name and role every write is recorded under (store/roles.h).
  try {
    state->op = ResolveOperator(state->options.user, state->options.role);
  } catch (const InputError&) {
    state->op = ResolveOperator("", "research");
  }
  user_edit_ = new QLineEdit(Q(state->op.user), this);
  user_edit_->setObjectName("user_edit");
  role_combo_ = new QComboBox(this);
  role_combo_->setObjectName("role_combo");
  for (Role r : {Role::kTechnician, Role::kTherapist, Role::kPhysicist, Role::kResearch}) {
    role_combo_->addItem(Q(RoleName(r)), static_cast<int>(r));
  }
  role_combo_->setCurrentIndex(role_combo_->findData(static_cast<int>(state->op.role)));
  role_help_ = new QLabel(this);
  role_help_->setWordWrap(true);
  connect(role_combo_, QOverload<int>::of(&QComboBox::currentIndexChanged), this, &CasePage::RoleChanged);
  connect(user_edit_, &QLineEdit::editingFinished, this, &CasePage::RoleChanged);
  store_edit_ = new QLineEdit(Q(state->options.store_path), this);
  case_edit_ = new QLineEdit(Q(state->options.case_dir), this);
  auto* form = new QFormLayout;
  auto* who_row = new QHBoxLayout;
  who_row->addWidget(user_edit_, 1);
  who_row->addWidget(new QLabel(tr("Role:"), this));
  who_row->addWidget(role_combo_);
  form->addRow(tr("Your name:"), who_row);
  form->addRow(QString(), role_help_);
  auto* store_row = new QHBoxLayout;
  store_row->addWidget(store_edit_);
  store_row->addWidget(BrowseButton(this, store_edit_, false));
  auto* case_row = new QHBoxLayout;
  case_row->addWidget(case_edit_);
  case_row->addWidget(BrowseButton(this, case_edit_, true));
  form->addRow(tr("Session store:"), store_row);
  form->addRow(tr("Case folder:"), case_row);

  auto* check_button = new QPushButton(tr("Check case"), this);
  connect(check_button, &QPushButton::clicked, this, &CasePage::RunCheck);
  status_ = new QLabel(this);
  problems_ = new QListWidget(this);
  store_summary_ = new QPlainTextEdit(this);
  store_summary_->setReadOnly(true);
  store_summary_->setFont(QFont("Monospace", 9));

  auto* layout = new QVBoxLayout(this);
  layout->addLayout(form);
  auto* check_row = new QHBoxLayout;
  check_row->addWidget(check_button);
  check_row->addWidget(status_, 1);
  layout->addLayout(check_row);
  layout->addWidget(new QLabel(tr("Problems found in the case:"), this));
  layout->addWidget(problems_, 1);
  layout->addWidget(new QLabel(tr("What the store holds:"), this));
  layout->addWidget(store_summary_, 1);
  connect(store_edit_, &QLineEdit::editingFinished, this, &CasePage::RefreshStore);
}

void CasePage::RoleChanged() {
  state_->op.user = user_edit_->text().trimmed().toStdString();
  state_->op.role = static_cast<Role>(role_combo_->currentData().toInt());
  state_->op.role_given = true;
  QStringList may;
  for (Action a : {Action::kPlan, Action::kApprovePlan, Action::kRunSession, Action::kTrack, Action::kEndSession}) {
    if (Permits(state_->op.role, a)) may << Q(ActionName(a));
  }
  role_help_->setText(tr("A %1's part: %2. Every change is recorded in the audit log under \"%3\". "
                         "(Names and roles are declared, not authenticated.)")
                          .arg(Q(RoleName(state_->op.role)), may.join(", "), Q(state_->op.Actor())));
}

void CasePage::initializePage() {
  RoleChanged();
  RefreshStore();
  if (!case_edit_->text().isEmpty()) RunCheck();
}

void CasePage::RefreshStore() {
  state_->options.store_path = store_edit_->text().toStdString();
  const std::string error = state_->OpenStore();
  store_summary_->setPlainText(error.empty() ? Q(DescribeStore(*state_->database)) : Q(error));
}

void CasePage::RunCheck() {
  state_->options.case_dir = case_edit_->text().toStdString();
  problems_->clear();
  CaseCheckOptions options;
  options.read_all_images = false;
  const CaseCheckReport report = CheckCase(state_->options.case_dir, options);
  for (const auto& p : report.problems) {
    auto* item = new QListWidgetItem(Q(p.ToString()), problems_);
    item->setForeground(p.severity == CaseProblem::Severity::kError ? QColor(200, 40, 40)
                                                                   : QColor(170, 120, 0));
  }
  if (report.problems.empty()) new QListWidgetItem(tr("No problems found."), problems_);
  status_->setText(report.ok() ? tr("Case OK: %1 sequences, %2 frames").arg(report.sequences).arg(report.frames)
                               : tr("The case has errors: fix them before planning."));
  status_->setStyleSheet(report.ok() ? "color: #2a7a2a; font-weight: bold;" : "color: #c02828; font-weight: bold;");
}

bool CasePage::validatePage() {
  RoleChanged();
  if (state_->op.user.empty()) {
    QMessageBox::warning(this, tr("Who are you?"), tr("Enter your name: every change is recorded under it."));
    return false;
  }
  state_->options.store_path = store_edit_->text().toStdString();
  state_->options.case_dir = case_edit_->text().toStdString();
  const std::string error = state_->OpenStore();
  if (!error.empty()) {
    QMessageBox::warning(this, tr("Session store"), Q(error));
    return false;
  }
  // A case with errors cannot be planned or scanned: stop here (no case at
  // all is fine: reviewing the store needs none).
  if (!state_->options.case_dir.empty()) {
    CaseCheckOptions options;
    options.read_all_images = false;
    const CaseCheckReport report = CheckCase(state_->options.case_dir, options);
    if (!report.ok()) {
      RunCheck();
      int errors = 0;
      for (const auto& p : report.problems) errors += p.severity == CaseProblem::Severity::kError;
      if (state_->options.unattended) {
        ARPOS_WARN("the case has " << errors << " error(s); going on (unattended)");
      } else if (QMessageBox::question(
                     this, tr("The case has errors"),
                     tr("The case folder has %1 error(s), listed on this page. Planning and the session stage "
                        "stop at them; tracking states each bad frame and goes on.\n\nGo on with this case?")
                         .arg(errors),
                     QMessageBox::Yes | QMessageBox::No, QMessageBox::No) != QMessageBox::Yes) {
        return false;
      }
    }
  }
  for (const std::string& note : RecoverInterruptedSessions(state_->database.get())) {
    if (!state_->options.unattended) QMessageBox::information(this, tr("Interrupted session"), Q(note));
  }
  return true;
}

// ---------------------------------------------------------------- planning

PlanningPage::PlanningPage(WizardState* state, QWidget* parent) : QWizardPage(parent), state_(state) {
  setTitle(tr("Planning"));
  setSubTitle(tr("A technician plans the case: the reference body surface and its desired pose in the room "
                 "(blue), and the room map from the room recording. A physicist then approves the plan."));
  model_view_ = new ModelView(this);
  plan_label_ = new QLabel(this);
  plan_label_->setWordWrap(true);
  approval_label_ = new QLabel(this);
  approval_label_->setWordWrap(true);
  room_frame_label_ = new QLabel(this);
  room_frame_label_->setObjectName("room_frame_warning");
  room_frame_label_->setWordWrap(true);
  room_frame_label_->setStyleSheet("color: #b03000;");
  room_frame_label_->hide();
  import_button_ = new QPushButton(tr("Plan the case: build the room map"), this);
  import_button_->setObjectName("plan_button");
  approve_button_ = new QPushButton(tr("Approve this plan…"), this);
  approve_button_->setObjectName("approve_button");
  progress_ = new QProgressBar(this);
  progress_->setRange(0, 100);
  cancel_button_ = new QPushButton(tr("Cancel"), this);
  cancel_button_->setEnabled(false);
  connect(import_button_, &QPushButton::clicked, this, &PlanningPage::ImportCase);
  connect(approve_button_, &QPushButton::clicked, this, &PlanningPage::ApproveShownPlan);
  connect(cancel_button_, &QPushButton::clicked, this, [this] {
    state_->worker->Cancel();
    cancel_button_->setEnabled(false);
    progress_->setFormat(tr("cancelling at the next step…"));
  });
  connect(state->worker, &Worker::Progress, this, [this](QString step, double fraction) {
    if (!running_here_) return;  // another page's job
    progress_->setValue(static_cast<int>(100 * fraction));
    progress_->setFormat(step + " %p%");
  });
  auto* layout = new QVBoxLayout(this);
  layout->addWidget(model_view_, 1);
  layout->addWidget(plan_label_);
  layout->addWidget(room_frame_label_);
  layout->addWidget(approval_label_);
  auto* row = new QHBoxLayout;
  row->addWidget(import_button_);
  row->addWidget(approve_button_);
  row->addWidget(progress_, 1);
  row->addWidget(cancel_button_);
  layout->addLayout(row);
}

void PlanningPage::initializePage() {
  if (!running_here_) {
    progress_->setValue(0);
    progress_->setFormat("%p%");
  }
  ShowLatestPlan();
}

void PlanningPage::UpdateButtons() {
  const bool busy = state_->worker->busy();
  const bool may_plan = Permits(state_->op.role, Action::kPlan);
  const bool may_approve = Permits(state_->op.role, Action::kApprovePlan);
  import_button_->setEnabled(!busy && may_plan);
  cancel_button_->setEnabled(busy && running_here_);
  import_button_->setToolTip(may_plan ? tr("Builds the room map from the case's room recording and stores it in the "
                                           "case's plan (made from the case if the patient has none not yet approved).")
                                      : tr("Planning is for a technician (or a research run)."));
  approve_button_->setVisible(may_approve);
  approve_button_->setEnabled(!busy && may_approve && shown_plan_approvable_);
  approve_button_->setToolTip(shown_plan_approvable_ ? tr("Approve the plan shown: its model, target pose and room "
                                                          "map. An approved plan cannot be changed.")
                                                     : tr("The plan shown is approved already or has no room map."));
}

void PlanningPage::ApproveShownPlan() {
  if (shown_plan_ <= 0 || !state_->database) return;
  bool ok = false;
  const QString note = QInputDialog::getText(
      this, tr("Approve plan %1").arg(shown_plan_),
      tr("Approve plan %1 as %2?\nIts reference model, target pose and room map can no longer be "
         "changed; therapists run sessions on it.%3\n\nNote (optional):")
          .arg(shown_plan_)
          .arg(Q(state_->op.Actor()))
          .arg(room_frame_warning_.isEmpty() ? QString() : "\n\n" + room_frame_warning_),
      QLineEdit::Normal, QString(), &ok);
  if (!ok) return;
  try {
    ApprovePlan(state_->database.get(), state_->op, PlanId(shown_plan_), note.toStdString());
  } catch (const std::exception& e) {
    QMessageBox::critical(this, tr("Approval refused"), Q(e.what()));
  }
  ShowLatestPlan();
}

void PlanningPage::ShowLatestPlan() {
  shown_plan_ = 0;
  shown_plan_approvable_ = false;
  approval_label_->clear();
  room_frame_warning_.clear();
  room_frame_label_->clear();
  room_frame_label_->hide();
  UpdateButtons();
  if (!state_->database) return;
  // The case's patient's newest plan, else the newest in the store.
  std::vector<PlanSummary> plans;
  if (!state_->options.case_dir.empty()) {
    if (const auto patient = state_->database->FindPatient(CasePatientId(state_->options.case_dir))) {
      plans = state_->database->ListPlans(patient->id, 1);
    }
  }
  if (plans.empty()) plans = state_->database->ListPlans(std::nullopt, 1);
  if (plans.empty()) {
    plan_label_->setText(tr("The store holds no plan yet: plan the case."));
    model_view_->ClearMeshes();
    return;
  }
  const auto plan = state_->database->GetPlan(plans.front().id);
  if (!plan) return;
  shown_plan_ = plan->id.value();
  shown_plan_approvable_ = !plan->approved() && plans.front().num_room_maps > 0;
  approval_label_->setText(plan->approved() ? tr("Plan %1 is %2. It cannot be changed.")
                                                   .arg(plan->id.value())
                                                   .arg(Q(DescribeApproval(*plan)))
                                            : tr("Plan %1 is NOT approved: a physicist approves it before "
                                                 "therapists run sessions on it.")
                                                  .arg(plan->id.value()));
  approval_label_->setStyleSheet(plan->approved() ? "color: #2a7a2a; font-weight: bold;"
                                                  : "color: #a06000; font-weight: bold;");
  UpdateButtons();
  const Rigid3d& target = plan->room_from_model_target;
  const Eigen::Vector3d r_deg = target.RotationVector() * (180.0 / M_PI);
  plan_label_->setText(
      Q(StringPrintf("Plan %lld \"%s\" of patient %s: reference model %s (%zu vertices). Target pose: "
                     "t = (%.1f, %.1f, %.1f) mm, rotation vector (%.2f, %.2f, %.2f) deg.",
                     static_cast<long long>(plan->id.value()), plan->name.c_str(),
                     plans.front().patient_external_id.c_str(), plan->reference_model_name.c_str(),
                     plan->reference_model.vertices.size(), 1000 * target.translation.x(),
                     1000 * target.translation.y(), 1000 * target.translation.z(), r_deg.x(), r_deg.y(),
                     r_deg.z())));
  model_view_->SetMesh("target", FromStoredMesh(plan->reference_model), target, 0.25, 0.45, 0.95);
  ShowRoomMap(plan->id);
  model_view_->ShowRoomAxes(0.3);
  model_view_->SetViewSubject(target);
  model_view_->ResetCamera();
}

void PlanningPage::ShowRoomMap(PlanId plan) {
  const auto id = state_->database->LatestRoomMap(plan);
  const auto map = id ? state_->database->GetRoomMap(*id) : std::nullopt;
  if (!map) {
    plan_label_->setText(plan_label_->text() + tr("\nNo room map yet for this plan."));
    return;
  }
  // Each mapped marker as its printed square (origin marker darker), each
  // landmark as a small octahedron (seen from any side).
  TriangleMesh markers, origin;
  for (const RoomMapMarker& m : map->markers) {
    AddQuad(m.marker_id == map->origin_marker_id ? &origin : &markers, m.corners_in_room);
  }
  std::vector<Eigen::Vector3d> landmarks;
  landmarks.reserve(map->landmarks_in_room.points.size());
  for (const auto& p : map->landmarks_in_room.points) landmarks.push_back(p.cast<double>());
  if (!markers.empty()) model_view_->SetMesh("room markers", markers, Rigid3d::Identity(), 0.95, 0.6, 0.1);
  if (!origin.empty()) model_view_->SetMesh("origin marker", origin, Rigid3d::Identity(), 0.75, 0.2, 0.05);
  model_view_->SetPoints("landmarks", landmarks, 0.85, 0.85, 0.85, 0.006);
  // Residuals, worst markers first: what a technician checks before use.
  std::vector<RoomMapMarker> sorted = map->markers;
  std::sort(sorted.begin(), sorted.end(),
            [](const RoomMapMarker& a, const RoomMapMarker& b) { return a.residual_px > b.residual_px; });
  QStringList worst;
  for (size_t i = 0; i < sorted.size() && i < 5; ++i) {
    worst << tr("%1: %2 px in %3 views").arg(sorted[i].marker_id).arg(sorted[i].residual_px, 0, 'f', 3).arg(sorted[i].num_observations);
  }
  plan_label_->setText(plan_label_->text() +
                       tr("\nRoom map %1: %2 markers (orange; origin %3 dark red), %4 keypoint landmarks (grey); "
                          "marker corner residual mean %5 px, max %6 px. Largest: %7.")
                           .arg(id->value())
                           .arg(map->markers.size())
                           .arg(map->origin_marker_id)
                           .arg(map->landmarks_in_room.points.size())
                           .arg(map->mean_residual_px, 0, 'f', 3)
                           .arg(map->max_residual_px, 0, 'f', 3)
                           .arg(worst.join(", ")));
  // How well the room frame is known where the patient lies: part of every
  // correction's bound in tracking (maps from before it was measured: none).
  if (map->room_frame_couch_sigma_mm && map->room_frame_tilt_sigma_deg &&
      map->room_frame_yaw_sigma_deg) {
    plan_label_->setText(
        plan_label_->text() +
        tr("\nRoom frame at the couch (1 sigma, from the origin marker and the map between it and "
           "the couch): position %1 mm, tilt %2 deg, yaw %3 deg; tracking adds 3 times these to "
           "every correction's bound.")
            .arg(*map->room_frame_couch_sigma_mm, 0, 'f', 2)
            .arg(*map->room_frame_tilt_sigma_deg, 0, 'f', 3)
            .arg(*map->room_frame_yaw_sigma_deg, 0, 'f', 3));
  }
  // What that means for tracking at the default tolerances, in the words
  // the tracking run uses, before anyone approves the plan.
  const RoomFrameNote note = DescribeRoomFrame(*map);
  room_frame_warning_ = note.blocks_in ? Q(AsSentence(note.plan_advice)) : QString();
  room_frame_label_->setText(room_frame_warning_);
  room_frame_label_->setVisible(note.blocks_in);
}

void PlanningPage::ImportCase() {
  if (state_->options.case_dir.empty()) {
    QMessageBox::warning(this, tr("Planning"), tr("Choose a case folder on the first page."));
    return;
  }
  import_button_->setEnabled(false);
  // The worker thread opens its own store connection: Database objects are
  // not shared between threads. The planning stage only (no session).
  const std::string store_path = state_->options.store_path;
  PlanRoomMapOptions options;
  options.case_dir = state_->options.case_dir;
  options.op = state_->op;
  running_here_ = true;
  progress_->setValue(0);
  const bool started = state_->worker->Start(
      [store_path, options](const ControllerCallbacks& callbacks) {
        auto database = SqliteDatabase::Open(store_path);
        return RunPlanRoomMap(options, database.get(), callbacks).Summary();
      },
      this,
      [this](bool ok, QString message) {
        running_here_ = false;
        progress_->setFormat(ok ? tr("planned %p%") : tr("stopped: nothing stored"));
        if (!ok) QMessageBox::critical(this, tr("Planning stopped"), message);
        ShowLatestPlan();
      });
  if (!started) running_here_ = false;
  UpdateButtons();
}

// ---------------------------------------------------------------- session

SessionPage::SessionPage(WizardState* state, QWidget* parent) : QWizardPage(parent), state_(state) {
  setTitle(tr("Session"));
  setSubTitle(tr("Treatment sessions: body marker map (white stickers), today's body surface coloured by its "
                 "distance to the reference model aligned to it (faint red), and the planned pose (blue)."));
  sessions_ = new QTableWidget(this);
  sessions_->setColumnCount(5);
  sessions_->setHorizontalHeaderLabels({tr("Session"), tr("Plan"), tr("Fraction"), tr("Started (UTC)"), tr("Status")});
  sessions_->horizontalHeader()->setStretchLastSection(true);
  sessions_->setEditTriggers(QAbstractItemView::NoEditTriggers);
  sessions_->setSelectionBehavior(QAbstractItemView::SelectRows);
  sessions_->setSelectionMode(QAbstractItemView::SingleSelection);
  sessions_->setMaximumHeight(150);
  connect(sessions_, &QTableWidget::currentCellChanged, this, [this](int row, int, int, int) { ShowSession(row); });
  model_view_ = new ModelView(this);
  details_ = new QLabel(this);
  details_->setWordWrap(true);
  details_->setTextInteractionFlags(Qt::TextSelectableByMouse);
  stages_ = new QLabel(this);
  stages_->setWordWrap(true);
  run_button_ = new QPushButton(tr("Run the session stage on the case's body scan"), this);
  run_button_->setObjectName("run_session_button");
  unapproved_box_ = new QCheckBox(tr("on a plan not approved (recorded)"), this);
  unapproved_box_->setObjectName("unapproved_box");
  unapproved_box_->setToolTip(tr("Sessions run on approved plans. For tests and research, run on a plan that is "
                                 "not approved; the session and the audit log say so."));
  complete_button_ = new QPushButton(tr("Complete session"), this);
  complete_button_->setObjectName("complete_session_button");
  abort_button_ = new QPushButton(tr("Abort session…"), this);
  abort_button_->setObjectName("abort_session_button");
  progress_ = new QProgressBar(this);
  progress_->setRange(0, 100);
  cancel_button_ = new QPushButton(tr("Cancel"), this);
  cancel_button_->setEnabled(false);
  connect(cancel_button_, &QPushButton::clicked, this, [this] {
    state_->worker->Cancel();
    cancel_button_->setEnabled(false);
    progress_->setFormat(tr("cancelling at the next step…"));
  });
  connect(run_button_, &QPushButton::clicked, this, &SessionPage::RunSessionStage);
  connect(complete_button_, &QPushButton::clicked, this, [this] { EndShownSession(true); });
  connect(abort_button_, &QPushButton::clicked, this, [this] { EndShownSession(false); });
  connect(state->worker, &Worker::Progress, this, [this](QString step, double fraction) {
    if (!running_here_) return;  // another page's job
    progress_->setValue(static_cast<int>(100 * fraction));
    progress_->setFormat(step + " %p%");
  });
  picks_label_ = new QLabel(this);
  picks_label_->setWordWrap(true);
  align_button_ = new QPushButton(tr("Align from picked pairs"), this);
  clear_picks_button_ = new QPushButton(tr("Clear picks"), this);
  connect(align_button_, &QPushButton::clicked, this, &SessionPage::AlignFromPicks);
  connect(clear_picks_button_, &QPushButton::clicked, this, [this] {
    ClearPicks();
    ShowPicks();
  });
  connect(model_view_, &ModelView::Picked, this,
          [this](QString slot, Eigen::Vector3d in_room, Eigen::Vector3d in_mesh) {
            if (slot == "reconstruction") {
              reconstruction_picks_.push_back(in_room);
              reconstruction_picks_room_.push_back(in_room);
              pick_note_.clear();
            } else if (slot == "aligned" || slot == "target") {
              model_picks_.push_back(in_mesh);
              model_picks_room_.push_back(in_room);
              pick_note_.clear();
            } else {
              pick_note_ = tr("That click hit the %1, not the model or the reconstruction: not counted.").arg(slot);
            }
            ShowPicks();
          });
  connect(model_view_, &ModelView::PickMissed, this, [this](QString) {
    pick_note_ = tr("That click hit no surface: not counted.");
    ShowPicks();
  });
  auto* layout = new QVBoxLayout(this);
  layout->addWidget(sessions_);
  layout->addWidget(model_view_, 1);
  layout->addWidget(details_);
  layout->addWidget(stages_);
  auto* manual = new QHBoxLayout;
  manual->addWidget(picks_label_, 1);
  manual->addWidget(clear_picks_button_);
  manual->addWidget(align_button_);
  layout->addLayout(manual);
  auto* row = new QHBoxLayout;
  row->addWidget(run_button_);
  row->addWidget(unapproved_box_);
  row->addWidget(progress_, 1);
  row->addWidget(cancel_button_);
  row->addWidget(complete_button_);
  row->addWidget(abort_button_);
  layout->addLayout(row);
  ShowPicks();
}

void SessionPage::UpdateButtons() {
  const bool busy = state_->worker->busy();
  const bool may_run = Permits(state_->op.role, Action::kRunSession);
  const bool may_end = Permits(state_->op.role, Action::kEndSession);
  run_button_->setEnabled(!busy && may_run);
  cancel_button_->setEnabled(busy && running_here_);
  run_button_->setToolTip(may_run ? QString() : tr("Sessions are for a therapist (or a research run)."));
  unapproved_box_->setVisible(may_run && state_->op.role != Role::kResearch);
  complete_button_->setEnabled(!busy && may_end && shown_session_open_);
  abort_button_->setEnabled(!busy && may_end && shown_session_open_);
  const QString why = !may_end ? tr("Ending sessions is for a therapist (or a research run).")
                      : !shown_session_open_ ? tr("The session shown is no longer open.")
                                             : QString();
  complete_button_->setToolTip(why);
  abort_button_->setToolTip(why);
}

void SessionPage::EndShownSession(bool completed) {
  if (shown_session_ <= 0 || !state_->database) return;
  QString reason;
  if (completed) {
    if (QMessageBox::question(this, tr("Complete session %1").arg(shown_session_),
                              tr("Complete session %1? It takes no more tracking runs.").arg(shown_session_)) !=
        QMessageBox::Yes) {
      return;
    }
  } else {
    bool ok = false;
    reason = QInputDialog::getText(this, tr("Abort session %1").arg(shown_session_),
                                   tr("Why is session %1 aborted? (recorded in the audit log)").arg(shown_session_),
                                   QLineEdit::Normal, QString(), &ok)
                 .trimmed();
    if (!ok) return;
    if (reason.isEmpty()) {
      QMessageBox::warning(this, tr("Abort session"), tr("Say why the session is aborted."));
      return;
    }
  }
  try {
    EndSession(state_->database.get(), state_->op, SessionId(shown_session_),
               completed ? SessionStatus::kCompleted : SessionStatus::kAborted, reason.toStdString());
  } catch (const std::exception& e) {
    QMessageBox::critical(this, tr("Session"), Q(e.what()));
  }
  ListSessions();
}

void SessionPage::ClearPicks() {
  model_picks_.clear();
  reconstruction_picks_.clear();
  model_picks_room_.clear();
  reconstruction_picks_room_.clear();
  pick_note_.clear();
}

void SessionPage::ShowPicks() {
  const size_t pairs = std::min(model_picks_.size(), reconstruction_picks_.size());
  picks_label_->setText(tr("Manual alignment: Shift+click a point on the model (red or blue), then the same "
                           "anatomy on the reconstruction; %1 on the model (magenta), %2 on the reconstruction "
                           "(cyan), %3 pairs (3 or more needed). %4")
                            .arg(model_picks_.size())
                            .arg(reconstruction_picks_.size())
                            .arg(pairs)
                            .arg(pick_note_));
  model_view_->SetPoints("model picks", model_picks_room_, 0.95, 0.2, 0.95);
  model_view_->SetPoints("reconstruction picks", reconstruction_picks_room_, 0.1, 0.9, 0.95);
  align_button_->setEnabled(pairs >= 3 && model_picks_.size() == reconstruction_picks_.size() &&
                            shown_reconstruction_ > 0);
}

void SessionPage::AlignFromPicks() {
  if (shown_reconstruction_ <= 0) return;
  align_button_->setEnabled(false);
  const std::string store_path = state_->options.store_path;
  const ReconstructionId reconstruction(shown_reconstruction_);
  const auto model_points = model_picks_;
  const auto reconstruction_points = reconstruction_picks_;
  const Operator op = state_->op;
  const bool started = state_->worker->Start(
      [=](const ControllerCallbacks&) {
        auto database = SqliteDatabase::Open(store_path);
        const ManualAlignmentResult r = AlignStoredReconstruction(database.get(), reconstruction, model_points,
                                                                  reconstruction_points, op);
        return StringPrintf("manual alignment %lld: picks %.1f mm RMS, after ICP fitness %.3f, rmse %.2f mm",
                            static_cast<long long>(r.icp_id.value()), 1000 * r.pick_rmse_m, r.fitness,
                            1000 * r.rmse_m);
      },
      this,
      [this](bool ok, QString message) {
        if (!ok) {
          QMessageBox::critical(this, tr("Manual alignment refused"), message);
        } else {
          ClearPicks();
        }
        ShowSession(sessions_->currentRow());
        ShowPicks();
      });
  if (!started) ShowPicks();
}

void SessionPage::initializePage() {
  if (!running_here_) {
    progress_->setValue(0);
    progress_->setFormat("%p%");
  }
  ListSessions();
}

void SessionPage::ListSessions() {
  shown_session_ = 0;
  shown_session_open_ = false;
  UpdateButtons();
  sessions_->setRowCount(0);
  model_view_->ClearMeshes();
  details_->clear();
  if (!state_->database) return;
  const auto sessions = state_->database->ListSessions(std::nullopt, 50);
  sessions_->setRowCount(static_cast<int>(sessions.size()));
  for (int row = 0; row < static_cast<int>(sessions.size()); ++row) {
    const auto& s = sessions[row];
    QString status = Q(ToString(s.status));
    if (s.status != SessionStatus::kOpen && !s.ended_by.empty()) status += tr(" by ") + Q(s.ended_by);
    if (!s.end_reason.empty()) status += ": " + Q(s.end_reason);
    if (s.on_unapproved_plan) status += tr(" (plan not approved)");
    const QStringList cells = {QString::number(s.id.value()), QString::number(s.plan_id.value()),
                               QString::number(s.fraction), Q(FormatUtcTime(s.started_unix_ms)), status};
    for (int c = 0; c < cells.size(); ++c) {
      auto* item = new QTableWidgetItem(cells[c]);
      item->setToolTip(cells[c]);
      sessions_->setItem(row, c, item);
    }
  }
  sessions_->resizeColumnsToContents();
  const StoreInfo info = state_->database->Info();
  stages_->setText(tr("Stored so far: %1 body marker maps, %2 reconstructions, %3 alignments.")
                       .arg(info.RowCount("body_marker_maps"))
                       .arg(info.RowCount("reconstructions"))
                       .arg(info.RowCount("alignments")));
  if (!sessions.empty()) sessions_->selectRow(0);  // the newest
}

void SessionPage::ShowSession(int row) {
  model_view_->ClearMeshes();
  details_->clear();
  const long long previous_reconstruction = shown_reconstruction_;
  shown_reconstruction_ = 0;
  shown_session_ = 0;
  shown_session_open_ = false;
  UpdateButtons();
  if (!state_->database || row < 0 || !sessions_->item(row, 0)) return;
  const SessionId session(sessions_->item(row, 0)->text().toLongLong());
  std::string notes;
  if (const auto record = state_->database->GetSession(session)) {
    shown_session_ = session.value();
    shown_session_open_ = record->status == SessionStatus::kOpen;
    notes = record->notes;
  }
  UpdateButtons();
  const PlanId plan_id(sessions_->item(row, 1)->text().toLongLong());
  QStringList lines;
  // What the session stage said of its recording (how well the body scan
  // is placed in the room, warnings with what to record): as the report
  // shows it, on top.
  if (!notes.empty()) lines << tr("Notes: %1").arg(Q(notes));
  const auto plan = state_->database->GetPlan(plan_id);
  TriangleMesh model;
  if (plan) model = FromStoredMesh(plan->reference_model);
  const auto maps = state_->database->ListBodyMarkerMapIds(session);
  if (!maps.empty()) {
    if (const auto map = state_->database->GetBodyMarkerMap(maps.back())) {
      lines << tr("Body marker map: %1 stickers (white), corner residual mean %2 px, max %3 px.")
                   .arg(map->markers.size())
                   .arg(map->mean_residual_px, 0, 'f', 3)
                   .arg(map->max_residual_px, 0, 'f', 3);
      lines << tr("Breathing: %1.").arg(Q(DescribeBreathing(*map)));
      // Each sticker as its printed square, 2 mm above the skin so the
      // surfaces do not hide it.
      TriangleMesh stickers;
      for (const auto& m : map->markers) {
        std::array<Eigen::Vector3d, 4> corners = MarkerCornersInMarker(map->marker_size_m);
        for (auto& c : corners) c = m.body_from_marker * (c + Eigen::Vector3d(0, 0, 0.002));
        AddQuad(&stickers, corners);
      }
      if (!stickers.empty()) model_view_->SetMesh("stickers", stickers, Rigid3d::Identity(), 0.95, 0.95, 1.0);
    }
  }
  const auto reconstructions = state_->database->ListReconstructionIds(session);
  if (reconstructions.empty()) {
    lines << tr("No reconstruction stored for this session.");
  } else if (const auto recon = state_->database->GetReconstruction(reconstructions.back())) {
    shown_reconstruction_ = recon->id.value();
    lines << tr("Reconstruction: %1 points from %2 frames%3.")
                 .arg(recon->cloud.points.size())
                 .arg(recon->num_frames_used)
                 .arg(recon->mesh ? tr(", mesh of %1 triangles").arg(recon->mesh->faces.size()) : QString());
    const auto alignments = state_->database->ListAlignments(recon->id);
    const TriangleMesh surface = recon->mesh ? FromStoredMesh(*recon->mesh) : TriangleMesh();
    if (!surface.empty() && (alignments.empty() || !plan)) {
      model_view_->SetMesh("reconstruction", surface, Rigid3d::Identity(), 0.75, 0.75, 0.72);
    }
    if (!alignments.empty() && plan) {
      const AlignmentRecord& final_alignment = alignments.back();
      const Rigid3d& room_from_model = final_alignment.reconstruction_from_model;
      // The reconstruction coloured by its distance to the aligned model, the
      // model as a faint red veil: a misalignment shows as yellow and red.
      if (!surface.empty()) {
        double within_2 = 0, within_5 = 0, median = 0;
        model_view_->SetColoredMesh("reconstruction", surface, Rigid3d::Identity(),
                                    DistanceColours(surface, model, room_from_model, &within_2, &within_5, &median));
        lines << tr("Today's surface coloured by its distance to the aligned model: green < 2 mm, yellow 5 mm, "
                    "red >= 10 mm, grey > 30 mm (not the patient). Median %1 mm; %2 % within 2 mm, %3 % within 5 mm.")
                     .arg(median, 0, 'f', 1)
                     .arg(100 * within_2, 0, 'f', 0)
                     .arg(100 * within_5, 0, 'f', 0);
      }
      model_view_->SetMesh("aligned", model, room_from_model, 0.9, 0.25, 0.2, 0.25);
      // The couch correction that would bring today's pose to the plan's, at
      // the isocentre (the model origin), in room axes.
      const Eigen::Vector3d shift_mm =
          1000 * (plan->room_from_model_target.translation - room_from_model.translation);
      const Eigen::Vector3d turn_deg =
          (plan->room_from_model_target * room_from_model.Inverse()).RotationVector() * (180.0 / M_PI);
      lines << tr("Final alignment: %1 (%2 stored for this reconstruction): fitness %3, RMSE %4 mm. %5")
                   .arg(Q(ToString(final_alignment.method)))
                   .arg(alignments.size())
                   .arg(final_alignment.fitness, 0, 'f', 3)
                   .arg(1000 * final_alignment.rmse_m, 0, 'f', 2)
                   .arg(Q(final_alignment.options));
      lines << tr("To reach the planned pose at scan time: shift (%1, %2, %3) mm, rotate (%4, %5, %6) deg "
                  "about the isocentre, room axes.")
                   .arg(shift_mm.x(), 0, 'f', 1)
                   .arg(shift_mm.y(), 0, 'f', 1)
                   .arg(shift_mm.z(), 0, 'f', 1)
                   .arg(turn_deg.x(), 0, 'f', 2)
                   .arg(turn_deg.y(), 0, 'f', 2)
                   .arg(turn_deg.z(), 0, 'f', 2);
    }
  }
  if (plan) model_view_->SetMesh("target", model, plan->room_from_model_target, 0.25, 0.45, 0.95, 0.35);
  if (shown_reconstruction_ != previous_reconstruction) ClearPicks();
  ShowPicks();
  details_->setText(lines.join("\n"));
  model_view_->SetViewSubject(plan ? std::optional<Rigid3d>(plan->room_from_model_target)
                                   : std::nullopt);
  model_view_->ResetCamera();
}

void SessionPage::RunSessionStage() {
  if (state_->options.case_dir.empty()) {
    QMessageBox::warning(this, tr("Session"), tr("Choose a case folder on the first page."));
    return;
  }
  run_button_->setEnabled(false);
  const std::string store_path = state_->options.store_path;
  SessionStageOptions options;
  options.case_dir = state_->options.case_dir;
  options.op = state_->op;
  options.unapproved = unapproved_box_->isVisible() && unapproved_box_->isChecked();
  running_here_ = true;
  progress_->setValue(0);
  const bool started = state_->worker->Start(
      [store_path, options](const ControllerCallbacks& callbacks) {
        auto database = SqliteDatabase::Open(store_path);
        SessionController controller(options, database.get(), callbacks);
        controller.Run();
        return controller.result().Summary();
      },
      this,
      [this](bool ok, QString message) {
        running_here_ = false;
        progress_->setFormat(ok ? tr("session stored %p%") : tr("stopped: nothing stored"));
        if (!ok) QMessageBox::critical(this, tr("Session stage stopped"), message);
        ListSessions();
        if (ok) stages_->setText(message.section('\n', 0, 1));  // which plan, and the session
      });
  if (!started) running_here_ = false;
  UpdateButtons();
}

// The audit page (AuditPage) is in ui/audit_page.cc.

}  // namespace arpos::ui
