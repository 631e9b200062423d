#include "ui/pages.h"

#include <QColor>
#include <QComboBox>
#include <QFileDialog>
#include <QFormLayout>
#include <QHBoxLayout>
#include <QHeaderView>
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
#include "sensor/case_check.h"
#include "store/database.h"
#include "store/describe.h"
#include "store/record_conversions.h"
#include "store/sqlite_database.h"
#include "ui/model_view.h"
#include "ui/worker.h"
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

// ---------------------------------------------------------------- case

CasePage::CasePage(WizardState* state, QWidget* parent) : QWizardPage(parent), state_(state) {
  setTitle(tr("Case and session store"));
  setSubTitle(tr("Choose where results are stored and the case folder to work on. "
                 "Check the case before planning."));
  store_edit_ = new QLineEdit(Q(state->options.store_path), this);
  case_edit_ = new QLineEdit(Q(state->options.case_dir), this);
  auto* form = new QFormLayout;
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

void CasePage::initializePage() {
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
  state_->options.store_path = store_edit_->text().toStdString();
  state_->options.case_dir = case_edit_->text().toStdString();
  const std::string error = state_->OpenStore();
  if (!error.empty()) {
    QMessageBox::warning(this, tr("Session store"), Q(error));
    return false;
  }
  return true;
}

// ---------------------------------------------------------------- planning

PlanningPage::PlanningPage(WizardState* state, QWidget* parent) : QWizardPage(parent), state_(state) {
  setTitle(tr("Planning"));
  setSubTitle(tr("Import the case into a plan: reference body surface and its desired pose in the room "
                 "(blue). The room map is built from the room recording."));
  model_view_ = new ModelView(this);
  plan_label_ = new QLabel(this);
  plan_label_->setWordWrap(true);
  import_button_ = new QPushButton(tr("Import case into a new plan"), this);
  progress_ = new QProgressBar(this);
  progress_->setRange(0, 100);
  connect(import_button_, &QPushButton::clicked, this, &PlanningPage::ImportCase);
  connect(state->worker, &Worker::Progress, this, [this](QString step, double fraction) {
    progress_->setValue(static_cast<int>(100 * fraction));
    progress_->setFormat(step + " %p%");
  });
  auto* layout = new QVBoxLayout(this);
  layout->addWidget(model_view_, 1);
  layout->addWidget(plan_label_);
  auto* row = new QHBoxLayout;
  row->addWidget(import_button_);
  row->addWidget(progress_, 1);
  layout->addLayout(row);
}

void PlanningPage::initializePage() { ShowLatestPlan(); }

void PlanningPage::ShowLatestPlan() {
  if (!state_->database) return;
  const auto plans = state_->database->ListPlans(std::nullopt, 1);
  if (plans.empty()) {
    plan_label_->setText(tr("The store holds no plan yet: import the case."));
    model_view_->ClearMeshes();
    return;
  }
  const auto plan = state_->database->GetPlan(plans.front().id);
  if (!plan) return;
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
  // landmark as a 1 cm triangle facing up.
  TriangleMesh markers, origin, landmarks;
  for (const RoomMapMarker& m : map->markers) {
    AddQuad(m.marker_id == map->origin_marker_id ? &origin : &markers, m.corners_in_room);
  }
  for (const auto& p : map->landmarks_in_room.points) {
    const int base = static_cast<int>(landmarks.vertices.size());
    landmarks.vertices.push_back(p + Eigen::Vector3f(-0.005f, -0.003f, 0));
    landmarks.vertices.push_back(p + Eigen::Vector3f(0.005f, -0.003f, 0));
    landmarks.vertices.push_back(p + Eigen::Vector3f(0, 0.006f, 0));
    landmarks.faces.emplace_back(base, base + 1, base + 2);
  }
  if (!markers.empty()) model_view_->SetMesh("room markers", markers, Rigid3d::Identity(), 0.95, 0.6, 0.1);
  if (!origin.empty()) model_view_->SetMesh("origin marker", origin, Rigid3d::Identity(), 0.75, 0.2, 0.05);
  if (!landmarks.empty()) model_view_->SetMesh("landmarks", landmarks, Rigid3d::Identity(), 0.85, 0.85, 0.85);
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
}

void PlanningPage::ImportCase() {
  if (state_->options.case_dir.empty()) {
    QMessageBox::warning(this, tr("Planning"), tr("Choose a case folder on the first page."));
    return;
  }
  import_button_->setEnabled(false);
  // The worker thread opens its own store connection: Database objects are
  // not shared between threads.
  const std::string store_path = state_->options.store_path;
  const std::string case_dir = state_->options.case_dir;
  const bool started = state_->worker->Start(
      [store_path, case_dir](const ControllerCallbacks& callbacks) {
        auto database = SqliteDatabase::Open(store_path);
        RunCaseOptions options;
        options.case_dir = case_dir;
        options.actor = "arpos gui";
        options.read_all_images = false;
        RunCaseController controller(options, database.get(), callbacks);
        controller.Run();
        return controller.result().Summary();
      },
      this,
      [this](bool ok, QString message) {
        import_button_->setEnabled(true);
        if (!ok) QMessageBox::critical(this, tr("Import failed"), message);
        ShowLatestPlan();
      });
  if (!started) import_button_->setEnabled(true);
}

// ---------------------------------------------------------------- session

SessionPage::SessionPage(WizardState* state, QWidget* parent) : QWizardPage(parent), state_(state) {
  setTitle(tr("Session"));
  setSubTitle(tr("Treatment sessions: body marker map, reconstruction of today's body surface (grey) and "
                 "the reference model aligned to it (red), with the planned pose (blue)."));
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
  progress_ = new QProgressBar(this);
  progress_->setRange(0, 100);
  connect(run_button_, &QPushButton::clicked, this, &SessionPage::RunSessionStage);
  connect(state->worker, &Worker::Progress, this, [this](QString step, double fraction) {
    progress_->setValue(static_cast<int>(100 * fraction));
    progress_->setFormat(step + " %p%");
  });
  picks_label_ = new QLabel(this);
  picks_label_->setWordWrap(true);
  align_button_ = new QPushButton(tr("Align from picked pairs"), this);
  clear_picks_button_ = new QPushButton(tr("Clear picks"), this);
  connect(align_button_, &QPushButton::clicked, this, &SessionPage::AlignFromPicks);
  connect(clear_picks_button_, &QPushButton::clicked, this, [this] {
    model_picks_.clear();
    reconstruction_picks_.clear();
    ShowPicks();
  });
  connect(model_view_, &ModelView::Picked, this,
          [this](QString slot, Eigen::Vector3d in_room, Eigen::Vector3d in_mesh) {
            if (slot == "reconstruction") {
              reconstruction_picks_.push_back(in_room);
            } else if (slot == "aligned" || slot == "target") {
              model_picks_.push_back(in_mesh);
            }
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
  row->addWidget(progress_, 1);
  layout->addLayout(row);
  ShowPicks();
}

void SessionPage::ShowPicks() {
  const size_t pairs = std::min(model_picks_.size(), reconstruction_picks_.size());
  picks_label_->setText(tr("Manual alignment: Shift+click a point on the model (red or blue), then the same "
                           "anatomy on the reconstruction (grey); %1 on the model, %2 on the reconstruction, "
                           "%3 pairs (3 or more needed).")
                            .arg(model_picks_.size())
                            .arg(reconstruction_picks_.size())
                            .arg(pairs));
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
  const bool started = state_->worker->Start(
      [=](const ControllerCallbacks&) {
        auto database = SqliteDatabase::Open(store_path);
        const ManualAlignmentResult r = AlignStoredReconstruction(database.get(), reconstruction, model_points,
                                                                  reconstruction_points, "arpos gui");
        return StringPrintf("manual alignment %lld: picks %.1f mm RMS, after ICP fitness %.3f, rmse %.2f mm",
                            static_cast<long long>(r.icp_id.value()), 1000 * r.pick_rmse_m, r.fitness,
                            1000 * r.rmse_m);
      },
      this,
      [this](bool ok, QString message) {
        if (!ok) {
          QMessageBox::critical(this, tr("Manual alignment refused"), message);
        } else {
          model_picks_.clear();
          reconstruction_picks_.clear();
        }
        ShowSession(sessions_->currentRow());
        ShowPicks();
      });
  if (!started) ShowPicks();
}

void SessionPage::initializePage() { ListSessions(); }

void SessionPage::ListSessions() {
  sessions_->setRowCount(0);
  model_view_->ClearMeshes();
  details_->clear();
  if (!state_->database) return;
  const auto sessions = state_->database->ListSessions(std::nullopt, 50);
  sessions_->setRowCount(static_cast<int>(sessions.size()));
  for (int row = 0; row < static_cast<int>(sessions.size()); ++row) {
    const auto& s = sessions[row];
    const QStringList cells = {QString::number(s.id.value()), QString::number(s.plan_id.value()),
                               QString::number(s.fraction), Q(FormatUtcTime(s.started_unix_ms)),
                               Q(ToString(s.status))};
    for (int c = 0; c < cells.size(); ++c) sessions_->setItem(row, c, new QTableWidgetItem(cells[c]));
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
  if (!state_->database || row < 0 || !sessions_->item(row, 0)) return;
  const SessionId session(sessions_->item(row, 0)->text().toLongLong());
  const PlanId plan_id(sessions_->item(row, 1)->text().toLongLong());
  QStringList lines;
  const auto plan = state_->database->GetPlan(plan_id);
  TriangleMesh model;
  if (plan) model = FromStoredMesh(plan->reference_model);
  const auto maps = state_->database->ListBodyMarkerMapIds(session);
  if (!maps.empty()) {
    if (const auto map = state_->database->GetBodyMarkerMap(maps.back())) {
      lines << tr("Body marker map: %1 stickers (green), corner residual mean %2 px, max %3 px.")
                   .arg(map->markers.size())
                   .arg(map->mean_residual_px, 0, 'f', 3)
                   .arg(map->max_residual_px, 0, 'f', 3);
      // Each sticker as its printed square, 2 mm above the skin so the
      // surfaces do not hide it.
      TriangleMesh stickers;
      for (const auto& m : map->markers) {
        std::array<Eigen::Vector3d, 4> corners = MarkerCornersInMarker(map->marker_size_m);
        for (auto& c : corners) c = m.body_from_marker * (c + Eigen::Vector3d(0, 0, 0.002));
        AddQuad(&stickers, corners);
      }
      if (!stickers.empty()) model_view_->SetMesh("stickers", stickers, Rigid3d::Identity(), 0.15, 0.85, 0.25);
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
    if (recon->mesh) {
      model_view_->SetMesh("reconstruction", FromStoredMesh(*recon->mesh), Rigid3d::Identity(), 0.75, 0.75, 0.72);
    }
    const auto alignments = state_->database->ListAlignments(recon->id);
    if (!alignments.empty() && plan) {
      const AlignmentRecord& final_alignment = alignments.back();
      const Rigid3d& room_from_model = final_alignment.reconstruction_from_model;
      model_view_->SetMesh("aligned", model, room_from_model, 0.9, 0.25, 0.2, 0.55);
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
  if (shown_reconstruction_ != previous_reconstruction) {
    model_picks_.clear();
    reconstruction_picks_.clear();
  }
  ShowPicks();
  details_->setText(lines.join("\n"));
  model_view_->ResetCamera();
}

void SessionPage::RunSessionStage() {
  if (state_->options.case_dir.empty()) {
    QMessageBox::warning(this, tr("Session"), tr("Choose a case folder on the first page."));
    return;
  }
  run_button_->setEnabled(false);
  const std::string store_path = state_->options.store_path;
  const std::string case_dir = state_->options.case_dir;
  const bool started = state_->worker->Start(
      [store_path, case_dir](const ControllerCallbacks& callbacks) {
        auto database = SqliteDatabase::Open(store_path);
        SessionStageOptions options;
        options.case_dir = case_dir;
        options.actor = "arpos gui";
        SessionController controller(options, database.get(), callbacks);
        controller.Run();
        return controller.result().Summary();
      },
      this,
      [this](bool ok, QString message) {
        run_button_->setEnabled(true);
        if (!ok) QMessageBox::critical(this, tr("Session stage failed"), message);
        ListSessions();
      });
  if (!started) run_button_->setEnabled(true);
}

// ---------------------------------------------------------------- audit

AuditPage::AuditPage(WizardState* state, QWidget* parent) : QWizardPage(parent), state_(state) {
  setTitle(tr("Audit"));
  setSubTitle(tr("Who did what and when: the store's append-only, hash-chained audit log."));
  verification_ = new QLabel(this);
  verification_->setWordWrap(true);
  table_ = new QTableWidget(this);
  table_->setColumnCount(5);
  table_->setHorizontalHeaderLabels({tr("Time (UTC)"), tr("Actor"), tr("Action"), tr("Entity"), tr("Details")});
  table_->horizontalHeader()->setStretchLastSection(true);
  table_->setEditTriggers(QAbstractItemView::NoEditTriggers);
  auto* export_button = new QPushButton(tr("Export report…"), this);
  connect(export_button, &QPushButton::clicked, this, &AuditPage::ExportReport);
  auto* layout = new QVBoxLayout(this);
  layout->addWidget(verification_);
  layout->addWidget(table_, 1);
  layout->addWidget(export_button, 0, Qt::AlignRight);
}

AuditVerification AuditPage::Verify() {
  AuditVerification v;
  if (auto* sqlite = dynamic_cast<SqliteDatabase*>(state_->database.get())) {
    v = sqlite->VerifyAudit();
  } else {
    v.problems.push_back("this store cannot verify its audit log");
  }
  if (v.ok()) {
    verification_->setText(tr("Audit log verified: %1 entries in the hash chain%2; the append-only triggers are "
                              "in place; every plan, session, map, alignment and tracking run has its entry.")
                               .arg(v.chained_entries)
                               .arg(v.legacy_entries > 0
                                        ? tr(" (%1 older entries from before the chain)").arg(v.legacy_entries)
                                        : QString()));
    verification_->setStyleSheet("QLabel { background-color: #2e7d32; color: white; padding: 8px; }");
  } else {
    verification_->setText(tr("Audit log NOT verified (%1 problem(s)): %2")
                               .arg(v.problems.size())
                               .arg(Q(v.problems.front())));
    verification_->setStyleSheet("QLabel { background-color: #c62828; color: white; padding: 8px; }");
  }
  verification_->setToolTip(Q(v.ToText()));
  return v;
}

void AuditPage::initializePage() {
  table_->setRowCount(0);
  verification_->clear();
  if (!state_->database) return;
  const std::int64_t first_bad_entry = Verify().first_bad_entry;
  const auto entries = state_->database->ListAudit();
  table_->setRowCount(static_cast<int>(entries.size()));
  for (int row = 0; row < static_cast<int>(entries.size()); ++row) {
    const auto& e = entries[row];
    const QStringList cells = {Q(FormatUtcTime(e.time_unix_ms)), Q(e.actor), Q(e.action), Q(e.entity), Q(e.details)};
    const bool bad = e.id.value() == first_bad_entry;
    for (int c = 0; c < cells.size(); ++c) {
      auto* item = new QTableWidgetItem(cells[c]);
      item->setToolTip(cells[c]);  // the whole text where the column cuts it
      if (bad) item->setBackground(QColor(255, 205, 205));
      table_->setItem(row, c, item);
    }
    if (bad) table_->scrollToItem(table_->item(row, 0));
  }
  table_->resizeColumnsToContents();
}

void AuditPage::ExportReport() {
  const QString path = QFileDialog::getSaveFileName(this, tr("Export report"), "arpos_report.txt",
                                                    tr("Text (*.txt)"));
  if (path.isEmpty() || !state_->database) return;
  std::ofstream out(path.toStdString());
  out << DescribeStore(*state_->database, 50) << "\n" << Verify().ToText() << "\nAudit log\n";
  for (const auto& e : state_->database->ListAudit()) {
    out << FormatUtcTime(e.time_unix_ms) << "  " << e.actor << "  " << e.action << "  " << e.entity << "  "
        << e.details << "\n";
  }
  if (!out) QMessageBox::critical(this, tr("Export report"), tr("Could not write %1").arg(path));
}

}  // namespace arpos::ui
