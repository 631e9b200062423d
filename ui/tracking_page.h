#pragma once
/// The wizard's tracking page: the live positioning screen. A recording of
/// the case (tracking/<name>) or of the session is tracked as if live against
/// the chosen session: the camera image with the reference model at the
/// current pose (red) and the planned pose (blue), the couch correction in
/// large type coloured by its tolerance state, its plot over the last 10 s,
/// the frame rate and latency. Play, pause and step; the run is stored when
/// the recording ends or the user stops. Tracking runs on worker threads
/// (live_tracking.h); leaving the page or closing the window while a run is
/// going asks first, then stops it and stores what was tracked.

#include <QString>
#include <QWizardPage>
#include <map>
#include <string>

#include "feedback/couch_correction.h"
#include "ui/live_tracking.h"
#include "ui/wizard.h"

class QComboBox;
class QLabel;
class QPushButton;

namespace arpos::ui {

class CorrectionPanel;
class CorrectionPlot;
class FrameView;

/// How the page starts when opened (arpos gui --play ...).
struct TrackingPageLaunch {
  bool play = false;            ///< start tracking the chosen recording at once
  QString sequence;             ///< choose this recording (its label, e.g. "tracking/seq_00")
  QString source;               ///< a camera source to list and choose (e.g. "openni2:", "sim:CASE")
  bool recorded_pace = true;    ///< false: as fast as tracking goes
  int pause_after_frames = -1;  ///< pause by itself after this many frames
};

class TrackingPage : public QWizardPage {
  Q_OBJECT
 public:
  TrackingPage(WizardState* state, QWidget* parent = nullptr);
  ~TrackingPage() override;
  void SetLaunch(const TrackingPageLaunch& launch) { launch_ = launch; }
  void initializePage() override;
  void cleanupPage() override;
  bool validatePage() override;
  bool running() const;
  /// What the Play / Pause button does: start, pause or go on.
  void Play();
  /// What the Step button does: one frame (starting the run paused if needed).
  void StepOnce();

 signals:
  /// The run ended: stored (ok, its summary) or failed (the error).
  void RunFinished(bool ok, QString message);
  /// A tracked frame's numbers are on screen.
  void FrameShown(int index);

 protected:
  bool eventFilter(QObject* watched, QEvent* event) override;

 private:
  void ListSessions();
  void ListRecordings();
  /// The chosen recording's first colour frame, while nothing is tracked.
  void ShowFirstFrame();
  void StartRun(bool paused);
  void UpdateButtons();
  /// Asks whether to stop the running run; true (and stopped, stored) if yes
  /// or if nothing runs.
  bool ConfirmStop();
  void OnFrame(const LiveFrame& frame);
  void OnFinished(bool ok, const QString& message, qint64 run_id, int frames);

  WizardState* state_;
  TrackingPageLaunch launch_;
  LiveTracking* live_;
  CouchTolerances tolerances_;
  QComboBox* sessions_;
  QComboBox* recordings_;
  QComboBox* pace_;
  QPushButton* play_button_;
  QPushButton* step_button_;
  QPushButton* stop_button_;
  QLabel* run_state_;  ///< RUNNING / PAUSED next to the buttons
  FrameView* frame_view_;
  CorrectionPanel* panel_;
  CorrectionPlot* plot_;
  QLabel* frame_label_;
  QLabel* status_;
  int images_shown_ = 0;  ///< overlay images shown in this run
  bool run_warned_ = false;  ///< the run started with a warning for all of it (amber to the end)
  bool filters_installed_ = false;
  bool launched_ = false;
  static const char kLiveTag[];
  /// Cameras found attached (label, spec), looked for once a page visit.
  std::vector<std::pair<QString, QString>> live_sources_;
  bool live_sources_listed_ = false;
  void ListLiveSources();
  /// Stored tracking recordings of the chosen session, by absolute path.
  std::map<std::string, long long> stored_recordings_;
};

}  // namespace arpos::ui
