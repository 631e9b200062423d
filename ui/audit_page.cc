// The audit page (ui/pages.h AuditPage): browse the store by patient, plan,
// session and run; the audit entries of what is selected; the artefact itself.
#include <QComboBox>
#include <QDateTime>
#include <QFileDialog>
#include <QHBoxLayout>
#include <QHeaderView>
#include <QInputDialog>
#include <QLabel>
#include <QLineEdit>
#include <QMessageBox>
#include <QPushButton>
#include <QScrollArea>
#include <QSet>
#include <QSplitter>
#include <QTableWidget>
#include <QTreeWidget>
#include <QVBoxLayout>
#include <algorithm>
#include <cmath>
#include <set>

#include "feedback/couch_correction.h"
#include "report/report_writer.h"
#include "report/session_report.h"
#include "store/database.h"
#include "store/describe.h"
#include "store/record_conversions.h"
#include "store/sqlite_database.h"
#include "tracking/tracking_stage.h"
#include "ui/correction_plot.h"
#include "ui/model_view.h"
#include "ui/pages.h"
#include "util/check.h"
#include "util/logging.h"
#include "util/string_util.h"

namespace arpos::ui {
namespace {

QString Q(const std::string& s) { return QString::fromStdString(s); }

constexpr int kEntityRole = Qt::UserRole;        // "session:3"; empty for the whole log
constexpr int kCoveredRole = Qt::UserRole + 1;   // the entities of the node and all under it
constexpr int kSessionRole = Qt::UserRole + 2;   // the session the node belongs to (0: none)

QString Entity(const char* kind, long long id) { return QString("%1:%2").arg(kind).arg(id); }

long long EntityId(const QString& entity) { return entity.section(':', 1).toLongLong(); }

QTreeWidgetItem* AddNode(QTreeWidgetItem* parent, const QString& text, const QString& entity, long long session) {
  auto* item = new QTreeWidgetItem(parent, {text});
  item->setToolTip(0, text);
  item->setData(0, kEntityRole, entity);
  item->setData(0, kSessionRole, session);
  return item;
}

// Every node covers its own entity and those of its children (and theirs).
QStringList Cover(QTreeWidgetItem* item) {
  QStringList covered;
  const QString own = item->data(0, kEntityRole).toString();
  if (!own.isEmpty()) covered << own;
  covered << item->data(0, kCoveredRole).toStringList();  // extra entities (room maps)
  for (int i = 0; i < item->childCount(); ++i) covered << Cover(item->child(i));
  item->setData(0, kCoveredRole, covered);
  return covered;
}

// A run's percentage in tolerance, for the tree.
QString RunLine(const ReportRun& run) {
  return QObject::tr("Run %1: %2 — %3 frames, %4 % in tolerance")
      .arg(run.run.id.value())
      .arg(Q(run.name))
      .arg(run.num_frames)
      .arg(ReportRun::Percent(run.num_in, run.num_frames), 0, 'f', 0);
}

}  // namespace

AuditPage::AuditPage(WizardState* state, QWidget* parent) : QWizardPage(parent), state_(state) {
  setTitle(tr("Audit"));
  setSubTitle(tr("Who did what and when: the store's append-only, hash-chained audit log, by patient, plan, "
                 "session and run."));
  verification_ = new QLabel(this);
  verification_->setWordWrap(true);

  tree_ = new QTreeWidget(this);
  tree_->setObjectName("audit_tree");
  tree_->setHeaderLabel(tr("Patients, plans, sessions, runs"));
  connect(tree_, &QTreeWidget::currentItemChanged, this, [this](QTreeWidgetItem* item) {
    ApplyFilters();
    ShowDetail(item);
  });

  auto* table_panel = new QWidget(this);
  text_filter_ = new QLineEdit(table_panel);
  text_filter_->setObjectName("audit_text_filter");
  text_filter_->setPlaceholderText(tr("Search actor, action, entity, details"));
  text_filter_->setClearButtonEnabled(true);
  action_filter_ = new QComboBox(table_panel);
  action_filter_->setObjectName("audit_action_filter");
  age_filter_ = new QComboBox(table_panel);
  age_filter_->setObjectName("audit_age_filter");
  age_filter_->addItem(tr("any time"), 0);
  for (int days : {1, 7, 30, 365}) age_filter_->addItem(tr("last %n day(s)", "", days), days);
  count_label_ = new QLabel(table_panel);
  count_label_->setObjectName("audit_count");
  connect(text_filter_, &QLineEdit::textChanged, this, &AuditPage::ApplyFilters);
  connect(action_filter_, QOverload<int>::of(&QComboBox::currentIndexChanged), this, &AuditPage::ApplyFilters);
  connect(age_filter_, QOverload<int>::of(&QComboBox::currentIndexChanged), this, &AuditPage::ApplyFilters);
  table_ = new QTableWidget(table_panel);
  table_->setObjectName("audit_table");
  table_->setColumnCount(5);
  table_->setHorizontalHeaderLabels({tr("Time (UTC)"), tr("Actor"), tr("Action"), tr("Entity"), tr("Details")});
  table_->horizontalHeader()->setStretchLastSection(true);
  table_->setEditTriggers(QAbstractItemView::NoEditTriggers);
  table_->setSelectionBehavior(QAbstractItemView::SelectRows);
  table_->verticalHeader()->setVisible(false);
  auto* filters = new QHBoxLayout;
  filters->addWidget(action_filter_, 1);
  filters->addWidget(age_filter_);
  filters->addWidget(count_label_);
  auto* table_layout = new QVBoxLayout(table_panel);
  table_layout->setContentsMargins(0, 0, 0, 0);
  table_layout->addWidget(text_filter_);
  table_layout->addLayout(filters);
  table_layout->addWidget(table_, 1);

  auto* detail_panel = new QWidget(this);
  detail_title_ = new QLabel(detail_panel);
  detail_title_->setObjectName("audit_detail_title");
  detail_title_->setWordWrap(true);
  QFont bold = detail_title_->font();
  bold.setBold(true);
  detail_title_->setFont(bold);
  model_view_ = new ModelView(detail_panel);
  model_view_->setMinimumSize(200, 200);
  run_plot_ = new CorrectionPlot(detail_panel);
  run_plot_->setObjectName("audit_run_plot");
  detail_text_ = new QLabel(detail_panel);
  detail_text_->setObjectName("audit_detail_text");
  detail_text_->setWordWrap(true);
  detail_text_->setTextInteractionFlags(Qt::TextSelectableByMouse);
  detail_text_->setAlignment(Qt::AlignTop | Qt::AlignLeft);
  auto* detail_layout = new QVBoxLayout(detail_panel);
  detail_layout->setContentsMargins(0, 0, 0, 0);
  detail_layout->addWidget(detail_title_);
  detail_layout->addWidget(model_view_, 1);
  detail_layout->addWidget(run_plot_, 1);
  // The text scrolls: a run's summary and notes can outgrow the panel, and a
  // label sized to all of its text squeezed the plot and ran off the bottom.
  auto* detail_scroll = new QScrollArea(detail_panel);
  detail_scroll->setObjectName("audit_detail_scroll");
  detail_scroll->setWidgetResizable(true);
  detail_scroll->setFrameShape(QFrame::NoFrame);
  detail_scroll->setWidget(detail_text_);
  detail_layout->addWidget(detail_scroll, 1);

  auto* splitter = new QSplitter(Qt::Horizontal, this);
  splitter->addWidget(tree_);
  splitter->addWidget(table_panel);
  splitter->addWidget(detail_panel);
  splitter->setStretchFactor(0, 2);
  splitter->setStretchFactor(1, 4);
  splitter->setStretchFactor(2, 4);
  splitter->setSizes({270, 480, 350});

  auto* export_button = new QPushButton(tr("Export report…"), this);
  connect(export_button, &QPushButton::clicked, this, &AuditPage::ExportReport);
  auto* layout = new QVBoxLayout(this);
  layout->addWidget(verification_);
  layout->addWidget(splitter, 1);
  layout->addWidget(export_button, 0, Qt::AlignRight);
  run_plot_->hide();
}

AuditPage::~AuditPage() = default;

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
  entries_.clear();
  reports_.clear();
  tree_->clear();
  first_bad_entry_ = 0;
  if (!state_->database) return;
  first_bad_entry_ = Verify().first_bad_entry;
  entries_ = state_->database->ListAudit();
  {
    const QSignalBlocker block(action_filter_);
    const QString chosen = action_filter_->currentData().toString();
    action_filter_->clear();
    action_filter_->addItem(tr("all actions"), QString());
    std::set<std::string> actions;
    for (const auto& e : entries_) actions.insert(e.action);
    for (const auto& a : actions) action_filter_->addItem(Q(a), Q(a));
    action_filter_->setCurrentIndex(std::max(0, action_filter_->findData(chosen)));
  }
  BuildTree();
}

void AuditPage::BuildTree() {
  const QSignalBlocker block(tree_);
  tree_->clear();
  Database* db = state_->database.get();
  auto* root = new QTreeWidgetItem(tree_, {tr("Whole log")});
  root->setData(0, kEntityRole, QString());
  // Room maps belong to their plan; their ids are found in the log.
  std::map<long long, QStringList> room_maps_by_plan;
  std::set<long long> patient_ids;
  for (const auto& e : entries_) {
    const QString entity = Q(e.entity);
    if (entity.startsWith("room_map:")) {
      try {
        if (const auto map = db->GetRoomMap(RoomMapId(EntityId(entity)))) {
          room_maps_by_plan[map->plan_id.value()] << entity;
        }
      } catch (const std::exception&) {
      }
    } else if (entity.startsWith("patient:")) {
      patient_ids.insert(EntityId(entity));
    }
  }
  const std::vector<PlanSummary> plans = db->ListPlans();
  for (const auto& p : plans) patient_ids.insert(p.patient_id.value());
  for (long long patient_id : patient_ids) {
    const auto patient = db->GetPatient(PatientId(patient_id));
    QString text = tr("Patient %1").arg(patient_id);
    if (patient) {
      text = tr("Patient %1%2").arg(Q(patient->external_id)).arg(
          patient->display_name.empty() ? QString() : QString(" (%1)").arg(Q(patient->display_name)));
    }
    auto* patient_node = AddNode(root, text, Entity("patient", patient_id), 0);
    std::vector<PlanSummary> own;
    for (const auto& p : plans) if (p.patient_id.value() == patient_id) own.push_back(p);
    std::reverse(own.begin(), own.end());  // oldest first
    for (const auto& p : own) {
      const QString approval = p.approved() ? tr("approved by %1").arg(Q(p.approved_by)) : tr("not approved");
      auto* plan_node = AddNode(patient_node, tr("Plan %1: %2 — %3").arg(p.id.value()).arg(Q(p.name)).arg(approval),
                                Entity("plan", p.id.value()), 0);
      if (!p.approved()) plan_node->setForeground(0, QColor(150, 70, 0));  // dark amber, not the verification red
      plan_node->setData(0, kCoveredRole, room_maps_by_plan[p.id.value()]);
      std::vector<SessionRecord> sessions = db->ListSessions(p.id);
      std::reverse(sessions.begin(), sessions.end());
      for (const auto& s : sessions) {
        const long long sid = s.id.value();
        QString line = tr("Session %1, fraction %2: %3").arg(sid).arg(s.fraction).arg(Q(ToString(s.status)));
        if (!s.operator_name.empty()) line += tr(", by %1").arg(Q(s.operator_name));
        if (!s.ended_by.empty()) line += tr(", ended by %1").arg(Q(s.ended_by));
        if (s.on_unapproved_plan) line += tr(" — plan not approved");
        auto* session_node = AddNode(plan_node, line, Entity("session", sid), sid);
        if (s.on_unapproved_plan) session_node->setForeground(0, QColor(150, 70, 0));  // dark amber, not the verification red
        std::unique_ptr<SessionReport> report;
        try {
          report = std::make_unique<SessionReport>(GatherSessionReport(db, s.id, state_->options.store_path));
        } catch (const std::exception& e) {
          ARPOS_WARN("audit page: session " << sid << ": " << e.what());
          continue;
        }
        for (const auto& m : report->body_marker_maps) {
          AddNode(session_node, tr("Body marker map %1: %2 stickers").arg(m.id.value()).arg(m.markers.size()),
                  Entity("body_marker_map", m.id.value()), sid);
        }
        for (const auto& r : report->reconstructions) {
          auto* recon_node = AddNode(session_node,
                                     tr("Reconstruction %1: %2 points, %3 frames")
                                         .arg(r.id.value())
                                         .arg(r.num_points)
                                         .arg(r.num_frames_used),
                                     Entity("reconstruction", r.id.value()), sid);
          for (const auto& a : r.alignments) {
            AddNode(recon_node,
                    tr("Alignment %1: %2, RMSE %3 mm%4")
                        .arg(a.record.id.value())
                        .arg(Q(ToString(a.record.method)))
                        .arg(1000 * a.record.rmse_m, 0, 'f', 2)
                        .arg(a.used_by_tracking ? tr(", tracked from") : QString()),
                    Entity("alignment", a.record.id.value()), sid);
          }
        }
        for (const auto& run : report->runs) {
          AddNode(session_node, RunLine(run), Entity("tracking_run", run.run.id.value()), sid);
        }
        reports_[sid] = std::move(report);
      }
    }
  }
  Cover(root);
  tree_->expandAll();
  tree_->setCurrentItem(root);
  ApplyFilters();
  ShowDetail(root);
}

bool AuditPage::SelectEntity(const QString& entity) {
  if (entity.isEmpty()) {
    tree_->setCurrentItem(tree_->topLevelItem(0));
    return tree_->topLevelItem(0) != nullptr;
  }
  for (QTreeWidgetItemIterator it(tree_); *it; ++it) {
    if ((*it)->data(0, kEntityRole).toString() == entity) {
      tree_->setCurrentItem(*it);
      tree_->scrollToItem(*it);
      return true;
    }
  }
  return false;
}

int AuditPage::ShownEntries() const { return table_->rowCount(); }

void AuditPage::ApplyFilters() {
  QTreeWidgetItem* node = tree_->currentItem();
  const bool whole_log = !node || node->data(0, kEntityRole).toString().isEmpty();
  QSet<QString> covered;
  if (!whole_log) {
    for (const QString& e : node->data(0, kCoveredRole).toStringList()) covered.insert(e);
  }
  const QString text = text_filter_->text().trimmed();
  const QString action = action_filter_->currentData().toString();
  const int days = age_filter_->currentData().toInt();
  const std::int64_t since_ms =
      days > 0 ? QDateTime::currentMSecsSinceEpoch() - static_cast<std::int64_t>(days) * 24 * 3600 * 1000 : 0;
  table_->setRowCount(0);
  table_->setSortingEnabled(false);
  int bad_row = -1;
  for (const auto& e : entries_) {
    if (!whole_log && !covered.contains(Q(e.entity))) continue;
    if (!action.isEmpty() && Q(e.action) != action) continue;
    if (days > 0 && e.time_unix_ms < since_ms) continue;
    const QStringList cells = {Q(FormatUtcTime(e.time_unix_ms)), Q(e.actor), Q(e.action), Q(e.entity), Q(e.details)};
    if (!text.isEmpty()) {
      bool hit = false;
      for (int c = 1; c < cells.size() && !hit; ++c) hit = cells[c].contains(text, Qt::CaseInsensitive);
      if (!hit) continue;
    }
    const int row = table_->rowCount();
    table_->insertRow(row);
    const bool bad = e.id.value() == first_bad_entry_;
    for (int c = 0; c < cells.size(); ++c) {
      auto* item = new QTableWidgetItem(cells[c]);
      item->setToolTip(cells[c]);  // the whole text where the column cuts it
      if (bad) item->setBackground(QColor(255, 205, 205));
      table_->setItem(row, c, item);
    }
    if (bad) bad_row = row;
  }
  table_->resizeColumnsToContents();
  // Who is often long ("root (research: no role given)"; the tooltip and
  // the details have it whole): narrower, so that the action shows beside it.
  table_->setColumnWidth(1, std::min(table_->columnWidth(1), 120));
  for (int c = 2; c < 4; ++c) table_->setColumnWidth(c, std::min(table_->columnWidth(c), 170));
  if (bad_row >= 0) table_->scrollToItem(table_->item(bad_row, 0));
  count_label_->setText(tr("%1 of %2 entries").arg(table_->rowCount()).arg(entries_.size()));
}

void AuditPage::ShowModels(long long plan_id, long long reconstruction_id, long long alignment_id,
                           QStringList* lines) {
  Database* db = state_->database.get();
  const auto plan = db->GetPlan(PlanId(plan_id));
  if (!plan) return;
  const TriangleMesh model = FromStoredMesh(plan->reference_model);
  model_view_->SetMesh("target", model, plan->room_from_model_target, 0.25, 0.45, 0.95, 0.35);
  model_view_->SetViewSubject(plan->room_from_model_target);
  if (reconstruction_id == 0) return;
  const auto recon = db->GetReconstruction(ReconstructionId(reconstruction_id));
  if (!recon) return;
  const TriangleMesh surface = recon->mesh ? FromStoredMesh(*recon->mesh) : TriangleMesh();
  std::optional<AlignmentRecord> alignment;
  if (alignment_id != 0) alignment = db->GetAlignment(AlignmentId(alignment_id));
  if (!alignment) {
    const auto all = db->ListAlignments(recon->id);
    if (!all.empty()) alignment = all.back();
  }
  if (!alignment) {
    if (!surface.empty()) model_view_->SetMesh("reconstruction", surface, Rigid3d::Identity(), 0.75, 0.75, 0.72);
    *lines << tr("Reconstruction %1 has no alignment: shown in grey.").arg(reconstruction_id);
    return;
  }
  const Rigid3d& room_from_model = alignment->reconstruction_from_model;
  if (!surface.empty()) {
    double within_2 = 0, within_5 = 0, median = 0;
    model_view_->SetColoredMesh("reconstruction", surface, Rigid3d::Identity(),
                                DistanceColours(surface, model, room_from_model, &within_2, &within_5, &median));
    *lines << tr("Reconstruction %1 coloured by its distance to the model at alignment %2: green < 2 mm, yellow "
                 "5 mm, red >= 10 mm, grey > 30 mm. Median %3 mm; %4 % within 2 mm, %5 % within 5 mm.")
                  .arg(reconstruction_id)
                  .arg(alignment->id.value())
                  .arg(median, 0, 'f', 1)
                  .arg(100 * within_2, 0, 'f', 0)
                  .arg(100 * within_5, 0, 'f', 0);
  }
  model_view_->SetMesh("aligned", model, room_from_model, 0.9, 0.25, 0.2, 0.25);
  *lines << tr("Alignment %1: %2, fitness %3, RMSE %4 mm, %5 inliers.")
                .arg(alignment->id.value())
                .arg(Q(ToString(alignment->method)))
                .arg(alignment->fitness, 0, 'f', 3)
                .arg(1000 * alignment->rmse_m, 0, 'f', 2)
                .arg(alignment->num_inliers);
  // The session stage's verdict on an automatic alignment ("ok", or what to
  // check).
  if (const std::string verdict = alignment->StageVerdict();
      AlignmentRecord::AsksForCheck(verdict)) {
    *lines << tr("Alignment %1, as the session stage found it: %2.")
                  .arg(alignment->id.value())
                  .arg(Q(verdict));
  }
}

void AuditPage::ShowRun(const SessionReport& report, long long run_id) {
  const ReportRun* run = nullptr;
  for (const auto& r : report.runs) if (r.run.id.value() == run_id) run = &r;
  if (!run) return;
  CouchTolerances tolerances;
  tolerances.translation_mm = run->run.tolerance_translation_mm;
  tolerances.rotation_deg = run->run.tolerance_rotation_deg;
  run_plot_->SetTolerances(tolerances);
  std::vector<std::pair<double, CouchCorrection>> frames;
  for (const ReportFrame& f : run->frames) {
    CouchCorrection c;
    c.state = f.status == TrackingFrameStatus::kInTolerance    ? CorrectionState::kIn
              : f.status == TrackingFrameStatus::kOutOfTolerance ? CorrectionState::kOut
                                                                 : CorrectionState::kLost;
    if (f.correction && c.state != CorrectionState::kLost) {
      c.lateral_mm = f.correction->translation_mm.x();
      c.longitudinal_mm = f.correction->translation_mm.y();
      c.vertical_mm = f.correction->translation_mm.z();
      c.pitch_deg = f.correction->rotation_deg.x();
      c.roll_deg = f.correction->rotation_deg.y();
      c.yaw_deg = f.correction->rotation_deg.z();
      // As the report measures them (report/session_report.h).
      c.translation_mm = f.correction->translation_mm.norm();
      c.rotation_deg = f.correction->rotation_deg.norm();
    } else {
      c.state = CorrectionState::kLost;
    }
    frames.emplace_back(f.time_s, c);
  }
  run_plot_->SetRun(frames);
  run_plot_->show();
  auto ms = [](const std::optional<double>& v) { return v ? QString("%1 ms").arg(*v, 0, 'f', 1) : QString("—"); };
  QStringList lines;
  lines << tr("%1 frames over %2 s, started %3; tolerance ±%4 mm, ±%5 deg.")
               .arg(run->num_frames)
               .arg(run->duration_s, 0, 'f', 1)
               .arg(Q(FormatUtcTime(run->run.started_unix_ms)))
               .arg(run->run.tolerance_translation_mm, 0, 'g', 3)
               .arg(run->run.tolerance_rotation_deg, 0, 'g', 3);
  lines << tr("Tracked %1, carried %2, lost %3. In tolerance %4 (%5 %), out %6, lost %7.")
               .arg(run->num_tracked)
               .arg(run->num_carried)
               .arg(run->num_lost_source)
               .arg(run->num_in)
               .arg(ReportRun::Percent(run->num_in, run->num_frames), 0, 'f', 0)
               .arg(run->num_out)
               .arg(run->num_lost);
  lines << tr("Time in tolerance %1 s of %2 s. Largest correction %3 mm, %4 deg.")
               .arg(run->time_in_tolerance_s, 0, 'f', 1)
               .arg(run->duration_s, 0, 'f', 1)
               .arg(run->max_translation_mm, 0, 'f', 1)
               .arg(run->max_rotation_deg, 0, 'f', 2);
  lines << tr("Latency mean %1, p95 %2 (%3 frames).")
               .arg(ms(run->latency_mean_ms))
               .arg(ms(run->latency_p95_ms))
               .arg(run->latency_frames);
  lines << tr("White: the shift's length and the turn's angle; red bands: frames without a pose; green band: "
              "the tolerance.");
  if (!run->run.summary.empty()) lines << Q(run->run.summary);
  detail_text_->setText(lines.join("\n"));
}

void AuditPage::ShowDetail(QTreeWidgetItem* item) {
  model_view_->ClearMeshes();
  run_plot_->hide();
  model_view_->hide();
  detail_text_->clear();
  detail_title_->clear();
  if (!item || !state_->database) return;
  detail_title_->setText(item->text(0));
  detail_title_->setToolTip(item->text(0));
  const QString entity = item->data(0, kEntityRole).toString();
  const QString kind = entity.section(':', 0, 0);
  const long long id = EntityId(entity);
  const long long session = item->data(0, kSessionRole).toLongLong();
  const auto found = reports_.find(session);
  const SessionReport* report = found != reports_.end() ? found->second.get() : nullptr;
  QStringList lines;
  bool three_d = false;
  try {
    if (entity.isEmpty()) {
      lines << tr("%1 audit entries; %n session(s) in the store. Choose a patient, plan, session or run at the "
                  "left.", "", static_cast<int>(reports_.size()))
                   .arg(entries_.size());
    } else if (kind == "patient") {
      lines << tr("%1 plan(s) under this patient.").arg(item->childCount());
    } else if (kind == "plan") {
      if (const auto plan = state_->database->GetPlan(PlanId(id))) {
        lines << tr("Reference model %1; created %2.")
                     .arg(Q(plan->reference_model_name))
                     .arg(Q(FormatUtcTime(plan->created_unix_ms)));
        lines << (plan->approved() ? tr("Approved by %1 at %2. Note: %3")
                                         .arg(Q(plan->approved_by))
                                         .arg(Q(FormatUtcTime(*plan->approved_unix_ms)))
                                         .arg(plan->approval_note.empty() ? tr("(none)") : Q(plan->approval_note))
                                   : tr("Not approved."));
        // Its newest room map and what the room frame does to tracking at the
        // default tolerances, as the planning page and the report say it.
        if (const auto map_id = state_->database->LatestRoomMap(plan->id)) {
          if (const auto map = state_->database->GetRoomMap(*map_id)) {
            lines << tr("Room map %1: %2 markers (origin %3), marker corner residual mean %4 px, "
                        "max %5 px.")
                         .arg(map_id->value())
                         .arg(map->markers.size())
                         .arg(map->origin_marker_id)
                         .arg(map->mean_residual_px, 0, 'f', 3)
                         .arg(map->max_residual_px, 0, 'f', 3);
            const RoomFrameNote note = DescribeRoomFrame(*map);
            if (const auto sigmas = RoomFrameSigmasOf(*map)) {
              lines << tr("Room frame at the couch: %1 mm, %2 deg (1 sigma).")
                           .arg(sigmas->position_mm, 0, 'f', 2)
                           .arg(sigmas->rotation_deg, 0, 'f', 3);
            }
            if (note.blocks_in) lines << Q(AsSentence(note.plan_advice));
          }
        } else {
          lines << tr("No room map yet.");
        }
        lines << tr("The model at its planned pose in blue.");
        three_d = true;
        ShowModels(id, 0, 0, &lines);
      }
    } else if (report && (kind == "session" || kind == "reconstruction" || kind == "alignment")) {
      const SessionRecord& s = report->session;
      if (kind == "session") {
        lines << tr("Session %1, fraction %2, %3; operator %4; started %5%6.")
                     .arg(s.id.value())
                     .arg(s.fraction)
                     .arg(Q(ToString(s.status)))
                     .arg(Q(s.operator_name))
                     .arg(Q(FormatUtcTime(s.started_unix_ms)))
                     .arg(s.ended_unix_ms ? tr(", ended %1").arg(Q(FormatUtcTime(*s.ended_unix_ms))) : QString());
        if (!s.ended_by.empty()) {
          lines << tr("Ended by %1%2.").arg(Q(s.ended_by)).arg(s.end_reason.empty() ? QString()
                                                                                      : tr(": %1").arg(Q(s.end_reason)));
        }
        if (s.on_unapproved_plan) lines << tr("This session ran on a plan that was not approved.");
        // The session stage's warnings, as it stored them in the notes.
        const std::string marker = "; warning: ";
        for (size_t at = s.notes.find(marker); at != std::string::npos;) {
          const size_t from = at + marker.size();
          const size_t next = s.notes.find(marker, from);
          lines << tr("Warning: %1")
                       .arg(
                           Q(s.notes.substr(from, next == std::string::npos ? next : next - from)));
          at = next;
        }
        if (report->approval) {
          lines << (report->approval->approved ? tr("Plan approved by %1.").arg(Q(report->approval->approved_by))
                                               : tr("Plan not approved."));
        }
      }
      long long recon_id = 0, alignment_id = 0;
      if (kind == "reconstruction") recon_id = id;
      if (kind == "alignment") {
        alignment_id = id;
        if (const auto a = state_->database->GetAlignment(AlignmentId(id))) recon_id = a->reconstruction_id.value();
      }
      if (kind == "session" && !report->reconstructions.empty()) recon_id = report->reconstructions.back().id.value();
      lines << tr("The plan's model at its planned pose in blue; the aligned model as a faint red veil.");
      three_d = true;
      ShowModels(s.plan_id.value(), recon_id, alignment_id, &lines);
    } else if (report && kind == "tracking_run") {
      ShowRun(*report, id);
      return;
    } else if (report && kind == "body_marker_map") {
      for (const auto& m : report->body_marker_maps) {
        if (m.id.value() != id) continue;
        lines << tr("%1 stickers of %2 mm; corner residual mean %3 px, max %4 px.")
                     .arg(m.markers.size())
                     .arg(1000 * m.marker_size_m, 0, 'f', 0)
                     .arg(m.mean_residual_px, 0, 'f', 3)
                     .arg(m.max_residual_px, 0, 'f', 3);
        lines << tr("Breathing: %1.").arg(Q(DescribeBreathing(m)));
      }
    }
  } catch (const std::exception& e) {
    lines << tr("Could not read it: %1").arg(Q(e.what()));
  }
  detail_text_->setText(lines.join("\n"));
  if (three_d) {
    model_view_->show();
    model_view_->ResetCamera();
  }
}

void AuditPage::ExportReport() {
  // The session report of `arpos report` (src/report), for the only session or one the user picks (newest first).
  if (!state_->database) return;
  const std::vector<SessionRecord> sessions = state_->database->ListSessions();
  if (sessions.empty()) {
    QMessageBox::information(this, tr("Export report"), tr("The store has no session to report."));
    return;
  }
  QStringList items;
  for (const SessionRecord& s : sessions) {
    items << tr("Session %1: fraction %2, %3, started %4")
                 .arg(s.id.value())
                 .arg(s.fraction)
                 .arg(ToString(s.status))
                 .arg(Q(FormatUtcTime(s.started_unix_ms)));
  }
  int index = 0;
  if (sessions.size() > 1) {
    bool chosen = false;
    const QString item = QInputDialog::getItem(this, tr("Export report"), tr("Session:"), items, 0, false, &chosen);
    if (!chosen) return;
    index = items.indexOf(item);
  }
  const SessionRecord& session = sessions[static_cast<std::size_t>(index)];
  const QString path = QFileDialog::getSaveFileName(this, tr("Export report"),
                                                    QString("arpos_report_session_%1.pdf").arg(session.id.value()),
                                                    tr("PDF (*.pdf);;HTML (*.html)"));
  if (path.isEmpty()) return;
  try {
    const std::optional<ReportFormat> format = ReportFormatForPath(path.toStdString());
    if (!format) ARPOS_INPUT_ERROR("the report's file name must end in .html or .pdf: " << path.toStdString());
    CheckReportOutputWritable(path.toStdString());
    WriteSessionReport(GatherSessionReport(state_->database.get(), session.id, state_->options.store_path), *format,
                       path.toStdString());
  } catch (const std::exception& e) {
    QMessageBox::critical(this, tr("Export report"), Q(e.what()));
  }
}

}  // namespace arpos::ui
