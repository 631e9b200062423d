#include "exe/cmd_gui.h"

#include <QApplication>
#include <QSurfaceFormat>
#include <QTimer>
#include <QVTKOpenGLNativeWidget.h>
#include <iostream>

#include "exe/args.h"
#include "store/store_path.h"
#include "ui/wizard.h"
#include "util/check.h"

namespace arpos {

int RunGuiCommand(const std::vector<std::string>& argv) {
  const char* usage =
      "usage: arpos gui [--store DB] [--case DIR] [--user NAME --role ROLE] [--page N --screenshot FILE.png]\n"
      "Opens the wizard: case and store, planning, session, tracking, audit.\n"
      "  --store DB          session store (default: $ARPOS_STORE, else ./arpos_store.db)\n"
      "  --case DIR          preselect a case folder\n"
      "  --user, --role      who (else $ARPOS_USER / $ARPOS_ROLE; changeable on the first page)\n"
      "  --page N            open page N (0 case, 1 planning, 2 session, 3 tracking, 4 audit)\n"
      "  --screenshot FILE   save a PNG of the window once it has drawn, then quit\n";
  const Args args(argv, {"store", "case", "page", "screenshot"}, {"help"});
  if (args.Has("help")) {
    std::cout << usage;
    return 0;
  }
  const long long page = args.GetInt("page", 0);
  if (page < 0 || page > 4) ARPOS_INPUT_ERROR("--page must be 0..4");

  // VTK's Qt widget needs its surface format before the application exists.
  QSurfaceFormat::setDefaultFormat(QVTKOpenGLNativeWidget::defaultFormat());
  int qt_argc = 1;
  char name[] = "arpos";
  char* qt_argv[] = {name, nullptr};
  QApplication app(qt_argc, qt_argv);
  ui::WizardSettings options;
  options.store_path = args.GetOr("store", DefaultStorePath());
  options.case_dir = args.GetOr("case", "");
  options.user = GivenOperatorFlags().user;
  options.role = GivenOperatorFlags().role;
  if (!options.role.empty() && !ParseRole(options.role)) {
    ARPOS_INPUT_ERROR("--role '" << options.role << "': not a role; the roles are " << RoleNames());
  }
  ui::ArposWizard wizard(options);
  wizard.show();
  for (long long i = 0; i < page; ++i) wizard.next();

  const auto screenshot = args.Get("screenshot");
  if (screenshot) {
    QTimer::singleShot(1500, &wizard, [&wizard, &app, path = *screenshot] {
      const bool saved = wizard.grab().save(QString::fromStdString(path));
      if (!saved) std::cerr << "arpos gui: could not save " << path << "\n";
      app.exit(saved ? 0 : 1);
    });
  }
  return app.exec();
}

}  // namespace arpos
