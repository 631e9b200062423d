#include "ui/tracking_page.h"

#include <QAbstractButton>
#include <QCloseEvent>
#include <QComboBox>
#include <QHBoxLayout>
#include <QKeyEvent>
#include <QLabel>
#include <QMessageBox>
#include <QMouseEvent>
#include <QPushButton>
#include <QVBoxLayout>
#include <QDateTime>
#include <QWizard>
#include <cstring>
#include <set>
#include <sqlite3.h>

#include "room_map/plan_stage.h"
#include "sensor/case_config.h"
#include "sensor/case_folder.h"
#include "sensor/sequence.h"
#include "sensor/source_plugin.h"
#include "store/database.h"
#include "store/describe.h"
#include "store/sqlite_database.h"
#include "tracking/tracking_stage.h"
#include "ui/correction_panel.h"
#include "ui/correction_plot.h"
#include "ui/frame_view.h"

namespace arpos::ui {

namespace {

QString Q(const std::string& s) { return QString::fromStdString(s); }

std::string AbsolutePath(const std::string& path) {
  std::error_code ec;
  const auto absolute = std::filesystem::absolute(path, ec);
  return (ec ? std::filesystem::path(path) : absolute).lexically_normal().string();
}

// Whether a session is open and has what tracking needs (a body marker map
// and an aligned reconstruction): the sessions LoadTrackingInputs accepts.
bool CanTrack(Database* database, SessionId session) {
  const std::optional<SessionRecord> record = database->GetSession(session);
  if (!record || record->status != SessionStatus::kOpen) return false;  // tracking runs on open sessions
  if (database->ListBodyMarkerMapIds(session).empty()) return false;
  for (const ReconstructionId& r : database->ListReconstructionIds(session)) {
    if (!database->ListAlignments(r).empty()) return true;
  }
  return false;
}

// The stored tracking recordings of a session (the store has no list call
// for them; read-only query on the same connection).
std::vector<RecordingRecord> TrackingRecordings(Database* database, SessionId session) {
  std::vector<RecordingRecord> out;
  auto* sqlite = dynamic_cast<SqliteDatabase*>(database);
  if (!sqlite) return out;
  sqlite3_stmt* statement = nullptr;
  if (sqlite3_prepare_v2(sqlite->RawHandle(),
                         "SELECT recording_id FROM recordings WHERE session_id = ? AND kind = 'tracking' "
                         "ORDER BY recording_id",
                         -1, &statement, nullptr) != SQLITE_OK) {
    return out;
  }
  sqlite3_bind_int64(statement, 1, session.value());
  std::vector<long long> ids;
  while (sqlite3_step(statement) == SQLITE_ROW) ids.push_back(sqlite3_column_int64(statement, 0));
  sqlite3_finalize(statement);
  for (long long id : ids) {
    if (auto recording = database->GetRecording(RecordingId(id))) out.push_back(*recording);
  }
  return out;
}

QString StateText(TrackingState state) {
  switch (state) {
    case TrackingState::kTracked: return QObject::tr("tracked");
    case TrackingState::kCarried: return QObject::tr("carried (no stickers, on the surface)");
    case TrackingState::kLost: break;
  }
  return QObject::tr("lost");
}

}  // namespace

// A live source's item in the recording list: this tag, then its spec.
const char TrackingPage::kLiveTag[] = "live-source:";

TrackingPage::TrackingPage(WizardState* state, QWidget* parent) : QWizardPage(parent), state_(state) {
  setTitle(tr("Tracking"));
  setSubTitle(tr("Live positioning: the patient now (red) and as planned (blue) over the camera image, and the "
                 "couch correction that brings the patient to the plan."));
  live_ = new LiveTracking(this);
  sessions_ = new QComboBox(this);
  recordings_ = new QComboBox(this);
  recordings_->setMinimumContentsLength(18);
  pace_ = new QComboBox(this);
  pace_->addItem(tr("Recorded pace"), true);
  pace_->addItem(tr("As fast as possible"), false);
  play_button_ = new QPushButton(tr("Play"), this);
  step_button_ = new QPushButton(tr("Step"), this);
  stop_button_ = new QPushButton(tr("Stop"), this);
  play_button_->setToolTip(tr("Track the recording as if live; again to pause"));
  step_button_->setToolTip(tr("Track one frame (pauses first)"));
  stop_button_->setToolTip(tr("End the run here and store the frames tracked so far"));
  run_state_ = new QLabel(this);
  run_state_->setMinimumWidth(80);
  run_state_->setAlignment(Qt::AlignCenter);
  frame_view_ = new FrameView(this);
  frame_view_->setMinimumSize(480, 360);
  panel_ = new CorrectionPanel(this);
  panel_->SetTolerances(tolerances_);
  plot_ = new CorrectionPlot(this);
  plot_->SetTolerances(tolerances_);
  plot_->setFixedHeight(200);
  frame_label_ = new QLabel(this);
  // A long note (a file path) is cut at the page's edge, not widening the
  // window; the whole line is its tooltip.
  frame_label_->setSizePolicy(QSizePolicy::Ignored, QSizePolicy::Preferred);
  status_ = new QLabel(this);
  status_->setWordWrap(true);
  status_->setTextInteractionFlags(Qt::TextSelectableByMouse);

  auto* controls = new QHBoxLayout;
  controls->addWidget(new QLabel(tr("Session:"), this));
  controls->addWidget(sessions_, 1);
  controls->addWidget(new QLabel(tr("Recording:"), this));
  controls->addWidget(recordings_, 1);
  controls->addWidget(pace_);
  controls->addWidget(play_button_);
  controls->addWidget(step_button_);
  controls->addWidget(stop_button_);
  controls->addWidget(run_state_);
  auto* views = new QHBoxLayout;
  views->addWidget(frame_view_, 3);
  views->addWidget(panel_, 2);
  auto* layout = new QVBoxLayout(this);
  layout->setContentsMargins(0, 0, 0, 0);
  layout->addLayout(controls);
  layout->addLayout(views, 1);
  layout->addWidget(plot_);
  layout->addWidget(frame_label_);
  layout->addWidget(status_);

  connect(sessions_, QOverload<int>::of(&QComboBox::currentIndexChanged), this, [this] { ListRecordings(); });
  connect(recordings_, QOverload<int>::of(&QComboBox::currentIndexChanged), this, [this] {
    ShowFirstFrame();
    UpdateButtons();
  });
  connect(play_button_, &QPushButton::clicked, this, &TrackingPage::Play);
  connect(step_button_, &QPushButton::clicked, this, &TrackingPage::StepOnce);
  connect(stop_button_, &QPushButton::clicked, this, [this] {
    live_->Stop();
    status_->setText(tr("Stopping: the frames tracked so far are stored as the run…"));
  });
  connect(live_, &LiveTracking::Started, this, [this](QString description) {
    // A second line is a warning for the whole run (a room frame too weak
    // for the tolerance): in amber, like an `out` frame.
    run_warned_ = description.contains('\n');
    status_->setStyleSheet(run_warned_ ? "color: #b06000; font-weight: bold;" : "");
    status_->setText(tr("Tracking against %1.").arg(description));
  });
  connect(live_, &LiveTracking::FrameTracked, this, [this](LiveFrame frame) { OnFrame(frame); });
  connect(live_, &LiveTracking::FrameImage, this, [this](cv::Mat image, int) {
    frame_view_->ShowColor(image);
    ++images_shown_;
    live_->ImageShown();
  });
  connect(live_, &LiveTracking::PausedChanged, this, [this](bool) { UpdateButtons(); });
  connect(live_, &LiveTracking::Finished, this,
          [this](bool ok, QString message, qint64 run_id, int frames) { OnFinished(ok, message, run_id, frames); });
  UpdateButtons();
}

TrackingPage::~TrackingPage() {
  // Stops a run still going and waits until it is stored.
  live_->StopAndWait();
}

bool TrackingPage::running() const { return live_->running(); }

void TrackingPage::initializePage() {
  if (!filters_installed_ && wizard()) {
    wizard()->installEventFilter(this);
    for (auto which : {QWizard::BackButton, QWizard::CancelButton}) {
      if (QAbstractButton* button = wizard()->button(which)) button->installEventFilter(this);
    }
    filters_installed_ = true;
  }
  live_sources_listed_ = false;
  ListSessions();
  if (!launch_.sequence.isEmpty()) {
    const int index = recordings_->findText(launch_.sequence);
    if (index >= 0) {
      recordings_->setCurrentIndex(index);
    } else {
      status_->setText(tr("No recording \"%1\" here.").arg(launch_.sequence));
    }
  }
  if (!launch_.source.isEmpty() && launch_.sequence.isEmpty()) {
    recordings_->setCurrentIndex(recordings_->findData(QString(kLiveTag) + launch_.source));
  }
  pace_->setCurrentIndex(launch_.recorded_pace ? 0 : 1);
  if (launch_.play && !launched_) {
    launched_ = true;
    StartRun(false);
  }
}

void TrackingPage::cleanupPage() {
  // Going back: the Back button already asked (eventFilter).
  live_->StopAndWait();
}

bool TrackingPage::validatePage() { return ConfirmStop(); }

bool TrackingPage::ConfirmStop() {
  if (!live_->running()) return true;
  const auto answer = QMessageBox::question(
      this, tr("Tracking is running"),
      tr("Stop tracking? The frames tracked so far are stored as the run."), QMessageBox::Yes | QMessageBox::No,
      QMessageBox::No);
  if (answer != QMessageBox::Yes) return false;
  live_->StopAndWait();
  return true;
}

bool TrackingPage::eventFilter(QObject* watched, QEvent* event) {
  if (!isVisible() || !live_->running()) return QWizardPage::eventFilter(watched, event);
  QWizard* w = wizard();
  const bool is_button = w && (watched == w->button(QWizard::BackButton) || watched == w->button(QWizard::CancelButton));
  bool leaving = false;
  if (is_button) {
    if (event->type() == QEvent::Shortcut) {  // Alt+B
      leaving = true;
    } else if (event->type() == QEvent::MouseButtonRelease) {
      auto* button = static_cast<QAbstractButton*>(watched);
      leaving = button->rect().contains(static_cast<QMouseEvent*>(event)->pos());
    } else if (event->type() == QEvent::KeyPress) {
      const int key = static_cast<QKeyEvent*>(event)->key();
      leaving = key == Qt::Key_Space || key == Qt::Key_Return || key == Qt::Key_Enter;
    }
  } else if (watched == w) {
    leaving = event->type() == QEvent::Close ||
              (event->type() == QEvent::KeyPress && static_cast<QKeyEvent*>(event)->key() == Qt::Key_Escape);
  }
  if (!leaving) return QWizardPage::eventFilter(watched, event);
  if (ConfirmStop()) return QWizardPage::eventFilter(watched, event);  // stopped: go on leaving
  if (is_button) static_cast<QAbstractButton*>(watched)->setDown(false);
  event->ignore();
  return true;  // stay
}

void TrackingPage::ListSessions() {
  sessions_->blockSignals(true);
  sessions_->clear();
  sessions_->blockSignals(false);
  if (!state_->database) {
    status_->setText(tr("No session store is open."));
    ListRecordings();
    return;
  }
  // The default: the session `arpos track` would use for this case.
  std::optional<long long> preferred;
  try {
    preferred = LoadTrackingInputs(state_->database.get(), std::nullopt,
                                   state_->options.case_dir.empty() ? "" : CasePatientId(state_->options.case_dir))
                    .session_id.value();
  } catch (const std::exception& e) {
    status_->setText(Q(e.what()));
  }
  sessions_->blockSignals(true);
  for (const SessionRecord& s : state_->database->ListSessions(std::nullopt, 100)) {
    if (!CanTrack(state_->database.get(), s.id)) continue;
    sessions_->addItem(tr("Session %1: plan %2, fraction %3").arg(s.id.value()).arg(s.plan_id.value()).arg(s.fraction),
                       QVariant::fromValue<qlonglong>(s.id.value()));
    sessions_->setItemData(sessions_->count() - 1, tr("started %1").arg(Q(FormatUtcTime(s.started_unix_ms))),
                           Qt::ToolTipRole);
    if (preferred && *preferred == s.id.value()) sessions_->setCurrentIndex(sessions_->count() - 1);
  }
  sessions_->blockSignals(false);
  if (sessions_->count() == 0) {
    status_->setText(tr("No open session with a body marker map and an alignment: run the session stage first "
                        "(previous page)."));
  }
  ListRecordings();
}

void TrackingPage::ListRecordings() {
  recordings_->clear();
  stored_recordings_.clear();
  std::vector<RecordingRecord> stored;
  if (state_->database && sessions_->currentIndex() >= 0) {
    stored = TrackingRecordings(state_->database.get(), SessionId(sessions_->currentData().toLongLong()));
    for (const RecordingRecord& r : stored) stored_recordings_[AbsolutePath(r.path)] = r.id.value();
  }
  std::set<std::string> listed;
  if (!state_->options.case_dir.empty()) {
    try {
      const CaseFolder folder = LoadCaseFolder(state_->options.case_dir);
      for (const auto& [name, dir] : folder.tracking) {
        recordings_->addItem(Q("tracking/" + name), Q(dir.string()));
        listed.insert(AbsolutePath(dir.string()));
      }
    } catch (const std::exception& e) {
      status_->setText(Q(e.what()));
    }
  }
  // The session's own recordings that are not the case's.
  for (const RecordingRecord& r : stored) {
    if (!listed.insert(AbsolutePath(r.path)).second) continue;
    if (r.path.rfind("live: ", 0) == 0) continue;  // a live run: nothing to play again
    recordings_->addItem(tr("recording %1: %2").arg(r.id.value()).arg(Q(r.name)), Q(r.path));
  }
  ListLiveSources();
  UpdateButtons();
}

void TrackingPage::ListLiveSources() {
  // The cameras attached now (listed once a page visit: OpenNI2 takes ~0.5 s
  // to look), the simulated camera of a simulated case, and the launch's.
  if (!live_sources_listed_) {
    live_sources_listed_ = true;
    live_sources_.clear();
    for (const auto& kind : SourceRegistry().Kinds()) {
      if (!kind.lister || kind.name == "replay" || kind.name == "sim") continue;
      try {
        for (const std::string& device : kind.lister().devices) {
          const std::string spec = device.substr(0, device.find(' '));
          live_sources_.emplace_back(tr("live: %1").arg(Q(device)), Q(spec));
        }
      } catch (const std::exception&) {
      }
    }
  }
  for (const auto& [label, spec] : live_sources_) recordings_->addItem(label, QString(kLiveTag) + spec);
  const std::filesystem::path case_dir = state_->options.case_dir;
  if (!case_dir.empty() && std::filesystem::exists(case_dir / "simulation.yaml") && SourceRegistry().Has("sim")) {
    recordings_->addItem(tr("live: simulated camera (%1)").arg(Q(case_dir.filename().string())),
                         QString(kLiveTag) + Q("sim:" + case_dir.string() + "?frames=300"));
  }
  if (!launch_.source.isEmpty()) {
    recordings_->addItem(tr("live: %1").arg(launch_.source), QString(kLiveTag) + launch_.source);
  }
}

void TrackingPage::ShowFirstFrame() {
  if (live_->running() || recordings_->currentIndex() < 0 || state_->options.case_dir.empty()) return;
  const QString data = recordings_->currentData().toString();
  if (data.startsWith(kLiveTag)) {
    frame_view_->ShowColor(cv::Mat());
    frame_label_->setStyleSheet("");
    frame_label_->setText(tr("Live camera %1: Play starts it; frames come at the camera's pace, and a frame more "
                             "than two behind is dropped (counted in the run's summary).")
                              .arg(data.mid(static_cast<int>(std::strlen(kLiveTag)))));
    return;
  }
  try {
    const CaseConfig config = LoadCaseConfig(std::filesystem::path(state_->options.case_dir) / "case.yaml");
    const Sequence sequence = Sequence::OpenEveryColourFrame(recordings_->currentData().toString().toStdString());
    if (sequence.size() == 0) return;
    std::string depth_problem;
    frame_view_->ShowColor(sequence.LoadFrameColourFirst(0, config.camera, &depth_problem).color);
    frame_label_->setStyleSheet("");
    frame_label_->setText(tr("%1: %2 frames, %3 s. Play tracks it as if live.")
                              .arg(recordings_->currentText())
                              .arg(sequence.size())
                              .arg(sequence.timestamp_s(sequence.size() - 1) - sequence.timestamp_s(0), 0, 'f', 1));
  } catch (const std::exception& e) {
    frame_label_->setText(Q(e.what()));
  }
}

void TrackingPage::UpdateButtons() {
  const bool running = live_->running();
  const bool paused = running && live_->paused();
  const bool may_track = Permits(state_->op.role, Action::kTrack);
  const bool can_start = may_track && recordings_->count() > 0 && sessions_->count() > 0;
  play_button_->setToolTip(may_track ? QString() : tr("Tracking is for a therapist (or a research run)."));
  play_button_->setText(running && !paused ? tr("Pause") : tr("Play"));
  play_button_->setEnabled(running || can_start);
  step_button_->setEnabled(paused || (!running && can_start));
  stop_button_->setEnabled(running);
  run_state_->setText(paused ? tr("PAUSED") : running ? tr("RUNNING") : QString());
  run_state_->setStyleSheet(paused    ? "background: #f0a000; color: #111; font-weight: bold; padding: 3px;"
                            : running ? "background: #2e7d32; color: white; font-weight: bold; padding: 3px;"
                                      : "");
  sessions_->setEnabled(!running);
  recordings_->setEnabled(!running);
  pace_->setEnabled(!running && !recordings_->currentData().toString().startsWith(kLiveTag));
}

void TrackingPage::Play() {
  if (!live_->running()) {
    StartRun(false);
  } else if (live_->paused()) {
    live_->Resume();
  } else {
    live_->Pause();
  }
  UpdateButtons();
}

void TrackingPage::StepOnce() {
  if (!live_->running()) {
    StartRun(true);
    live_->Step();
  } else if (live_->paused()) {
    live_->Step();
  }
  UpdateButtons();
}

void TrackingPage::StartRun(bool paused) {
  if (live_->running()) return;
  if (recordings_->currentIndex() < 0 || sessions_->currentIndex() < 0 || state_->options.case_dir.empty()) {
    status_->setText(tr("Choose a case (first page), a session with an alignment and a recording."));
    return;
  }
  LiveRunRequest request;
  request.store_path = state_->options.store_path;
  request.case_dir = state_->options.case_dir;
  const QString data = recordings_->currentData().toString();
  if (data.startsWith(kLiveTag)) {
    request.source_spec = data.mid(static_cast<int>(std::strlen(kLiveTag))).toStdString();
    request.name = QDateTime::currentDateTime().toString("'live-'yyyyMMdd-HHmmss").toStdString();
  } else {
    request.sequence_dir = data.toStdString();
    request.name = request.sequence_dir.filename().string();
    if (request.name.empty()) request.name = request.sequence_dir.parent_path().filename().string();
  }
  request.session = SessionId(sessions_->currentData().toLongLong());
  request.op = state_->op;
  const auto stored = stored_recordings_.find(AbsolutePath(request.sequence_dir.string()));
  if (stored != stored_recordings_.end()) request.recording_id = RecordingId(stored->second);
  request.tolerances = tolerances_;
  request.recorded_pace = pace_->currentData().toBool();
  request.start_paused = paused;
  request.pause_after_frames = launch_.pause_after_frames;
  launch_.pause_after_frames = -1;  // once
  plot_->Clear();
  images_shown_ = 0;
  panel_->Clear(tr("Starting…"));
  frame_label_->clear();
  status_->setStyleSheet("");
  run_warned_ = false;
  status_->setText(tr("Loading the session and the recording…"));
  live_->Start(request);
  UpdateButtons();
}

void TrackingPage::OnFrame(const LiveFrame& frame) {
  QString reason;
  if (frame.correction.state == CorrectionState::kLost) {
    // What to do first, then why.
    const QString advice = QString::fromUtf8(TrackingLossAdvice(frame.loss));
    reason = advice.isEmpty() ? frame.note : frame.note.isEmpty() ? advice : advice + "\n" + frame.note;
  }
  panel_->ShowCorrection(frame.correction, reason);
  panel_->ShowRate(frame.frames_per_s, frame.latency_ms);
  plot_->Add(frame.timestamp_s, frame.correction);
  QString text = (frame.count > 0 ? tr("Frame %1 of %2").arg(frame.index + 1).arg(frame.count)
                                  : tr("Frame %1 (live)").arg(frame.index + 1)) +
                 tr(", t = %1 s: %2").arg(frame.timestamp_s, 0, 'f', 3).arg(StateText(frame.state));
  if (!frame.readable) text += tr(" (colour image unreadable)");
  else if (!frame.has_depth) text += tr(" (no depth image)");
  if (!frame.note.isEmpty()) text += tr(". %1").arg(frame.note.left(240));
  frame_label_->setText(text);
  frame_label_->setToolTip(text);
  frame_label_->setStyleSheet(frame.readable && frame.has_depth ? "" : "color: #c02828; font-weight: bold;");
  emit FrameShown(frame.index);
}

void TrackingPage::OnFinished(bool ok, const QString& message, qint64 run_id, int frames) {
  if (ok) {
    status_->setText(tr("Tracking run %1 stored (%2 frames, overlay shown for %3): %4")
                         .arg(run_id)
                         .arg(frames)
                         .arg(images_shown_)
                         .arg(message));
    // Stored, but a run that could not read `in` (its room frame too weak
    // for the tolerance) stays amber: the summary says why.
    status_->setStyleSheet(run_warned_ ? "color: #b06000; font-weight: bold;" : "color: #2a7a2a;");
  } else {
    status_->setText(tr("Tracking failed: %1").arg(message));
    status_->setStyleSheet("color: #c02828; font-weight: bold;");
    panel_->Clear(tr("Not tracking"));
  }
  UpdateButtons();
  emit RunFinished(ok, message);
}

}  // namespace arpos::ui
