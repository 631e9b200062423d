#include "exe/cmd_gui.h"

#include <QAbstractButton>
#include <QApplication>
#include <QLineEdit>
#include <QMessageBox>
#include <QSurfaceFormat>
#include <QTimer>
#include <QVTKOpenGLNativeWidget.h>
#include <iostream>

#include "exe/args.h"
#include "store/store_path.h"
#include "ui/pages.h"
#include "ui/tracking_page.h"
#include "ui/wizard.h"
#include "util/check.h"

namespace arpos {

int RunGuiCommand(const std::vector<std::string>& argv) {
  const char* usage =
      "usage: arpos gui [--store DB] [--case DIR] [--user NAME --role ROLE] [--page N] [--play ...] [--screenshot FILE.png ...]\n"
      "Opens the wizard: case and store, planning, session, tracking, audit.\n"
      "  --store DB          session store (default: $ARPOS_STORE, else ./arpos_store.db)\n"
      "  --case DIR          preselect a case folder\n"
      "  --user, --role      who (else $ARPOS_USER / $ARPOS_ROLE; changeable on the first page)\n"
      "  --page N            open page N (0 case, 1 planning, 2 session, 3 tracking, 4 audit)\n"
      "  --screenshot FILE   save a PNG of the window once it has drawn, then quit\n"
      "  --screenshot-delay MS  take it this long after the window opened (default 1500)\n"
      "  --screenshot-when-done take it when the tracking run has ended and is stored (with --play)\n"
      "Tracking page (--page 3):\n"
      "  --play              start tracking the recording at once (quitting stops it and\n"
      "                      stores the frames tracked so far)\n"
      "  --sequence NAME     the recording to choose, as listed (e.g. tracking/seq_00)\n"
      "  --source SPEC       list this camera source and choose it (`arpos sources`: openni2:,\n"
      "                      sim:CASE?frames=N)\n"
      "  --fast              as fast as tracking goes (default: the recording's pace)\n"
      "  --pause-after N     pause by itself once N frames are tracked\n"
      "  --steps N           press Step N times, 1.5 s apart, from 2 s after opening\n"
      "Audit page (--page 4):\n"
      "  --select ENTITY     select the tree node of ENTITY (e.g. session:1, tracking_run:2)\n"
      "  --filter TEXT       type TEXT into the audit table's search field\n"
      "                      (either prints how many entries the table shows)\n"
      "For tests:\n"
      "  --close-after MS    close the window after MS ms, as its close button does\n"
      "  --answer-close A    answer a question the window asks on closing: yes or no\n"
      "                      (its text is printed)\n";
  const Args args(argv,
                  {"store", "case", "page", "screenshot", "screenshot-delay", "sequence", "source", "pause-after",
                   "close-after", "answer-close", "steps", "select", "filter"},
                  {"help", "play", "fast", "screenshot-when-done"});
  if (args.Has("help")) {
    std::cout << usage;
    return 0;
  }
  const long long page = args.GetInt("page", 0);
  if (page < 0 || page > 4) ARPOS_INPUT_ERROR("--page must be 0..4");
  const long long steps = args.GetInt("steps", 0);
  if (steps < 0) ARPOS_INPUT_ERROR("--steps must be >= 0");
  const bool tracking_options = args.Has("play") || args.Has("sequence") || args.Has("source") || args.Has("fast") || args.Has("steps") ||
                                args.Has("pause-after") || args.Has("screenshot-when-done");
  if (tracking_options && page != ui::ArposWizard::kTrackingPage) {
    ARPOS_INPUT_ERROR("--play, --sequence, --source, --fast, --steps, --pause-after and --screenshot-when-done need --page 3");
  }
  if ((args.Has("select") || args.Has("filter")) && page != ui::ArposWizard::kAuditPage) {
    ARPOS_INPUT_ERROR("--select and --filter need --page 4");
  }
  if (args.Has("screenshot-when-done") && !args.Has("play")) ARPOS_INPUT_ERROR("--screenshot-when-done needs --play");
  const long long delay_ms = args.GetInt("screenshot-delay", 1500);
  if (delay_ms < 0) ARPOS_INPUT_ERROR("--screenshot-delay must be >= 0");
  const long long pause_after = args.GetInt("pause-after", -1);
  if (args.Has("pause-after") && pause_after < 0) ARPOS_INPUT_ERROR("--pause-after must be >= 0");
  const long long close_after = args.GetInt("close-after", -1);
  if (args.Has("close-after") && close_after < 0) ARPOS_INPUT_ERROR("--close-after must be >= 0");
  const std::string answer_close = args.GetOr("answer-close", "");
  if (!answer_close.empty() && answer_close != "yes" && answer_close != "no") {
    ARPOS_INPUT_ERROR("--answer-close must be yes or no");
  }

  // VTK's Qt widget needs its surface format before the application exists.
  QSurfaceFormat::setDefaultFormat(QVTKOpenGLNativeWidget::defaultFormat());
  int qt_argc = 1;
  char name[] = "arpos";
  char* qt_argv[] = {name, nullptr};
  QApplication app(qt_argc, qt_argv);
  ui::WizardSettings options;
  options.store_path = args.GetOr("store", DefaultStorePath());
  options.case_dir = args.GetOr("case", "");
  options.unattended = page > 0 || args.Has("screenshot");
  options.user = GivenOperatorFlags().user;
  options.role = GivenOperatorFlags().role;
  if (!options.role.empty() && !ParseRole(options.role)) {
    ARPOS_INPUT_ERROR("--role '" << options.role << "': not a role; the roles are " << RoleNames());
  }
  ui::ArposWizard wizard(options);
  auto* tracking = qobject_cast<ui::TrackingPage*>(wizard.page(ui::ArposWizard::kTrackingPage));
  ARPOS_CHECK(tracking != nullptr, "the wizard has no tracking page");
  ui::TrackingPageLaunch launch;
  launch.play = args.Has("play");
  launch.sequence = QString::fromStdString(args.GetOr("sequence", ""));
  launch.source = QString::fromStdString(args.GetOr("source", ""));
  launch.recorded_pace = !args.Has("fast");
  launch.pause_after_frames = static_cast<int>(pause_after);
  tracking->SetLaunch(launch);
  QObject::connect(tracking, &ui::TrackingPage::RunFinished, &wizard, [](bool ok, QString message) {
    std::cout << "arpos gui: tracking " << (ok ? "run stored: " : "failed: ") << message.toStdString() << std::endl;
  });
  wizard.show();
  for (long long i = 0; i < page; ++i) wizard.next();

  if (args.Has("select") || args.Has("filter")) {
    auto* audit = qobject_cast<ui::AuditPage*>(wizard.page(ui::ArposWizard::kAuditPage));
    ARPOS_CHECK(audit != nullptr, "the wizard has no audit page");
    const std::string entity = args.GetOr("select", "");
    if (!audit->SelectEntity(QString::fromStdString(entity))) {
      ARPOS_INPUT_ERROR("--select " << entity << ": the audit page has no such node");
    }
    if (args.Has("filter")) {
      if (auto* edit = audit->findChild<QLineEdit*>("audit_text_filter")) {
        edit->setText(QString::fromStdString(args.GetOr("filter", "")));
      }
    }
    std::cout << "arpos gui: audit shows " << audit->ShownEntries() << " of " << audit->TotalEntries()
              << " entries" << std::endl;
  }
  const auto screenshot = args.Get("screenshot");
  if (screenshot) {
    auto take = [&wizard, &app, path = *screenshot] {
      const bool saved = wizard.grab().save(QString::fromStdString(path));
      if (!saved) std::cerr << "arpos gui: could not save " << path << "\n";
      app.exit(saved ? 0 : 1);
    };
    if (args.Has("screenshot-when-done")) {
      // After the last frame's image has had time to arrive.
      QObject::connect(tracking, &ui::TrackingPage::RunFinished, &wizard,
                       [&wizard, take] { QTimer::singleShot(500, &wizard, take); });
    } else {
      QTimer::singleShot(static_cast<int>(delay_ms), &wizard, take);
    }
  }
  for (long long i = 0; i < steps; ++i) {
    QTimer::singleShot(static_cast<int>(2000 + 1500 * i), tracking, [tracking] { tracking->StepOnce(); });
  }
  if (close_after >= 0) {
    QTimer::singleShot(static_cast<int>(close_after), &wizard, [&wizard, answer_close] {
      if (!answer_close.empty()) {
        // The question is modal: answer it from inside its own event loop.
        QTimer::singleShot(500, &wizard, [answer_close] {
          auto* box = qobject_cast<QMessageBox*>(QApplication::activeModalWidget());
          if (!box) {
            std::cout << "arpos gui: no question on closing" << std::endl;
            return;
          }
          std::cout << "arpos gui: asked \"" << box->text().toStdString() << "\", answering " << answer_close
                    << std::endl;
          if (QAbstractButton* button = box->button(answer_close == "yes" ? QMessageBox::Yes : QMessageBox::No)) {
            button->click();
          }
        });
      }
      wizard.close();
    });
  }
  // Quitting while a run goes on stops it; the wizard's pages store what was tracked.
  return app.exec();
}

}  // namespace arpos
