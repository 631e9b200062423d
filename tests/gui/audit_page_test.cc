// The audit page on a store filled by run-case on the sample session: the
// tree of patient, plan, session and runs; a run's node filters the table
// and shows its correction plot; the search field narrows the table. The
// wizard is built in this process; run-case is the real executable.
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <QApplication>
#include <QComboBox>
#include <QImage>
#include <QLabel>
#include <QLineEdit>
#include <QTableWidget>
#include <QTreeWidget>
#include <QTreeWidgetItemIterator>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <string>

#include "ui/pages.h"
#include "ui/wizard.h"
#include "util/file.h"

namespace arpos {
namespace {

int RunArpos(const std::string& args, std::string* output) {
  const std::string command = std::string(ARPOS_EXECUTABLE) + " " + args + " 2>&1";
  FILE* pipe = popen(command.c_str(), "r");
  if (!pipe) return -1;
  char buffer[4096];
  size_t n;
  while ((n = fread(buffer, 1, sizeof(buffer), pipe)) > 0) output->append(buffer, n);
  const int status = pclose(pipe);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

std::filesystem::path Sample() { return std::filesystem::path(ARPOS_SAMPLE_SESSIONS_DIR) / "demo_xtion"; }

class AuditPageTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    if (!std::getenv("DISPLAY")) return;
    dir_ = new TempDir();
    std::string out;
    suite_ok_ = RunArpos("run-case " + Sample().string() + " --store " + Store(), &out) == 0;
    if (!suite_ok_) std::cerr << out;
  }
  static void TearDownTestSuite() {
    delete dir_;
    dir_ = nullptr;
  }
  static std::string Store() { return (dir_->path() / "store.db").string(); }

  void SetUp() override {
    if (!std::getenv("DISPLAY")) GTEST_SKIP() << "no X display: run through tools/test.sh (xvfb-run)";
    ASSERT_TRUE(suite_ok_) << "run-case on the sample failed";
    static int argc = 1;
    static char name[] = "audit_page_test";
    static char* argv[] = {name, nullptr};
    if (!QApplication::instance()) app_ = new QApplication(argc, argv);
    ui::WizardSettings settings;
    settings.store_path = Store();
    settings.case_dir = Sample().string();
    settings.unattended = true;
    wizard_ = std::make_unique<ui::ArposWizard>(settings);
    wizard_->resize(1280, 900);
    wizard_->show();
    for (int i = 0; i < ui::ArposWizard::kAuditPage; ++i) wizard_->next();
    ASSERT_EQ(wizard_->currentId(), ui::ArposWizard::kAuditPage);
    page_ = qobject_cast<ui::AuditPage*>(wizard_->currentPage());
    ASSERT_NE(page_, nullptr);
    tree_ = page_->findChild<QTreeWidget*>("audit_tree");
    table_ = page_->findChild<QTableWidget*>("audit_table");
    ASSERT_NE(tree_, nullptr);
    ASSERT_NE(table_, nullptr);
  }

  // The texts of all tree nodes, one per line.
  QString TreeText() const {
    QStringList lines;
    for (QTreeWidgetItemIterator it(tree_); *it; ++it) lines << (*it)->text(0);
    return lines.join('\n');
  }
  void Settle() {
    for (int i = 0; i < 20; ++i) QApplication::processEvents();
  }

  static TempDir* dir_;
  static bool suite_ok_;
  static QApplication* app_;
  std::unique_ptr<ui::ArposWizard> wizard_;
  ui::AuditPage* page_ = nullptr;
  QTreeWidget* tree_ = nullptr;
  QTableWidget* table_ = nullptr;
};

TempDir* AuditPageTest::dir_ = nullptr;
bool AuditPageTest::suite_ok_ = false;
QApplication* AuditPageTest::app_ = nullptr;

TEST_F(AuditPageTest, TreeHoldsPatientPlanSessionAndRuns) {
  const QString text = TreeText();
  EXPECT_TRUE(text.contains("Whole log")) << text.toStdString();
  EXPECT_TRUE(text.contains("Patient ")) << text.toStdString();
  EXPECT_TRUE(text.contains("Plan 1:")) << text.toStdString();
  // run-case is a research run: its plan is not approved.
  EXPECT_TRUE(text.contains("not approved")) << text.toStdString();
  EXPECT_TRUE(text.contains("Session 1, fraction 1: completed")) << text.toStdString();
  EXPECT_TRUE(text.contains("Run 1:")) << text.toStdString();
  EXPECT_TRUE(text.contains("% in tolerance")) << text.toStdString();
  EXPECT_TRUE(text.contains("Reconstruction ")) << text.toStdString();
  EXPECT_TRUE(text.contains("Alignment ")) << text.toStdString();
  EXPECT_TRUE(text.contains("Body marker map ")) << text.toStdString();
  // The whole log is shown at first.
  EXPECT_GT(page_->TotalEntries(), 5);
  EXPECT_EQ(page_->ShownEntries(), page_->TotalEntries());
  auto* count = page_->findChild<QLabel*>("audit_count");
  ASSERT_NE(count, nullptr);
  EXPECT_EQ(count->text(), QString("%1 of %1 entries").arg(page_->TotalEntries()));
  EXPECT_FALSE(page_->SelectEntity("session:999"));
}

TEST_F(AuditPageTest, SelectingARunFiltersTheTableAndPlotsTheRun) {
  ASSERT_TRUE(page_->SelectEntity("tracking_run:1"));
  Settle();
  const int shown = page_->ShownEntries();
  EXPECT_GT(shown, 0);
  EXPECT_LT(shown, page_->TotalEntries());
  for (int row = 0; row < table_->rowCount(); ++row) {
    EXPECT_EQ(table_->item(row, 3)->text(), "tracking_run:1");
    EXPECT_EQ(table_->item(row, 4)->toolTip(), table_->item(row, 4)->text());
  }
  // The run's plot: visible, with the axes' colours (lateral and pitch light
  // blue: legend and points), the magnitudes in white, the dashed tolerance
  // lines and the sample run's lost frame as a red band.
  QWidget* plot = page_->findChild<QWidget*>("audit_run_plot");
  ASSERT_NE(plot, nullptr);
  ASSERT_TRUE(plot->isVisible());
  const QImage image = plot->grab().toImage();
  int blue = 0, tolerance_green = 0, lost_red = 0, white = 0;
  for (int y = 0; y < image.height(); ++y) {
    for (int x = 0; x < image.width(); ++x) {
      const QColor c = image.pixelColor(x, y);
      if (std::abs(c.red() - 79) < 20 && std::abs(c.green() - 195) < 20 && std::abs(c.blue() - 247) < 20) ++blue;
      if (c.green() > 120 && c.green() > c.red() + 40 && c.green() > c.blue() + 40) ++tolerance_green;
      if (c.red() > 235 && c.green() > 235 && c.blue() > 235) ++white;
      if (c.red() > c.green() + 50 && c.red() > c.blue() + 50) ++lost_red;
    }
  }
  EXPECT_GT(blue, 60);
  EXPECT_GT(white, 60);  // the magnitudes' legend and points
  EXPECT_GT(lost_red, 1000);
  EXPECT_GT(tolerance_green, 50);
  auto* text = page_->findChild<QLabel*>("audit_detail_text");
  ASSERT_NE(text, nullptr);
  EXPECT_TRUE(text->text().contains("frames over")) << text->text().toStdString();
  EXPECT_TRUE(text->text().contains("Latency mean")) << text->text().toStdString();

  // The session covers its runs, its records and itself: more rows than the run.
  ASSERT_TRUE(page_->SelectEntity("session:1"));
  Settle();
  EXPECT_GT(page_->ShownEntries(), shown);
  // With the session stage's warnings (the sample's scan is placed by 2 frames).
  EXPECT_TRUE(text->text().contains("Warning: the body scan is placed in the room by 2 frame(s)"))
      << text->text().toStdString();
  EXPECT_FALSE(plot->isVisible());
  // Back to the whole log.
  ASSERT_TRUE(page_->SelectEntity(""));
  EXPECT_EQ(page_->ShownEntries(), page_->TotalEntries());
}

TEST_F(AuditPageTest, TextAndActionFiltersNarrowTheTable) {
  auto* search = page_->findChild<QLineEdit*>("audit_text_filter");
  ASSERT_NE(search, nullptr);
  const int total = page_->TotalEntries();
  search->setText("TRACKING_RUN");  // case-insensitive, matches the entity
  EXPECT_GT(page_->ShownEntries(), 0);
  EXPECT_LT(page_->ShownEntries(), total);
  for (int row = 0; row < table_->rowCount(); ++row) {
    QString all;
    for (int c = 1; c < 5; ++c) all += table_->item(row, c)->text() + " ";
    EXPECT_TRUE(all.contains("tracking_run", Qt::CaseInsensitive)) << all.toStdString();
  }
  search->setText("no entry says this");
  EXPECT_EQ(page_->ShownEntries(), 0);
  auto* count = page_->findChild<QLabel*>("audit_count");
  EXPECT_EQ(count->text(), QString("0 of %1 entries").arg(total));
  search->clear();
  EXPECT_EQ(page_->ShownEntries(), total);

  auto* action = page_->findChild<QComboBox*>("audit_action_filter");
  ASSERT_NE(action, nullptr);
  ASSERT_GT(action->count(), 2);
  action->setCurrentIndex(1);
  const QString chosen = action->currentText();
  EXPECT_GT(page_->ShownEntries(), 0);
  EXPECT_LT(page_->ShownEntries(), total);
  for (int row = 0; row < table_->rowCount(); ++row) EXPECT_EQ(table_->item(row, 2)->text(), chosen);
}

// The executable's --select and --filter (page 4): a run's node shows its
// plot (the plot's dark background and the lateral axis' light blue, absent
// from the whole log's screenshot) and fewer entries; the filter narrows.
TEST_F(AuditPageTest, SelectOptionShowsTheRunInTheScreenshot) {
  wizard_.reset();
  auto shoot = [](const std::string& extra, const std::string& png, std::string* out) {
    return RunArpos("gui --store " + Store() + " --case " + Sample().string() + " --page 4 " + extra +
                        " --screenshot " + png,
                    out);
  };
  const std::string whole_png = (dir_->path() / "whole.png").string();
  const std::string run_png = (dir_->path() / "run.png").string();
  std::string out;
  ASSERT_EQ(shoot("", whole_png, &out), 0) << out;
  out.clear();
  ASSERT_EQ(shoot("--select tracking_run:1", run_png, &out), 0) << out;
  EXPECT_NE(out.find("arpos gui: audit shows 1 of "), std::string::npos) << out;
  auto count = [](const QImage& image, QColor want, int within) {
    int n = 0;
    for (int y = 0; y < image.height(); ++y) {
      for (int x = 0; x < image.width(); ++x) {
        const QColor c = image.pixelColor(x, y);
        n += std::abs(c.red() - want.red()) <= within && std::abs(c.green() - want.green()) <= within &&
             std::abs(c.blue() - want.blue()) <= within;
      }
    }
    return n;
  };
  const QImage whole(QString::fromStdString(whole_png)), run(QString::fromStdString(run_png));
  ASSERT_FALSE(whole.isNull());
  ASSERT_FALSE(run.isNull());
  const QColor background(22, 24, 30), lateral(79, 195, 247);
  EXPECT_GT(count(run, background, 2), 8000);
  EXPECT_LT(count(whole, background, 2), 1000);
  EXPECT_GT(count(run, lateral, 15), count(whole, lateral, 15) + 80);
  out.clear();
  // The session's two alignments (automatic, then ICP), case-insensitively.
  ASSERT_EQ(shoot("--select session:1 --filter ADD_ALIGNMENT", (dir_->path() / "filtered.png").string(), &out), 0)
      << out;
  EXPECT_NE(out.find("arpos gui: audit shows 2 of "), std::string::npos) << out;
}

}  // namespace
}  // namespace arpos
