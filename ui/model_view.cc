#include "ui/model_view.h"

#include <QVBoxLayout>
#include <QVTKOpenGLNativeWidget.h>
#include <map>
#include <vtkActor.h>
#include <vtkAxesActor.h>
#include <vtkCallbackCommand.h>
#include <vtkCellArray.h>
#include <vtkCellPicker.h>
#include <vtkRenderWindowInteractor.h>
#include <vtkGenericOpenGLRenderWindow.h>
#include <vtkNew.h>
#include <vtkPoints.h>
#include <vtkPolyData.h>
#include <vtkPolyDataMapper.h>
#include <vtkPolyDataNormals.h>
#include <vtkPointData.h>
#include <vtkUnsignedCharArray.h>
#include <vtkProperty.h>
#include <vtkRenderer.h>
#include <vtkSmartPointer.h>

namespace arpos::ui {

struct ModelView::Impl {
  QVTKOpenGLNativeWidget* widget = nullptr;
  vtkNew<vtkGenericOpenGLRenderWindow> window;
  vtkNew<vtkRenderer> renderer;
  std::map<std::string, vtkSmartPointer<vtkActor>> actors;
  std::map<std::string, Rigid3d> room_from_mesh;
  vtkNew<vtkCellPicker> picker;
  vtkNew<vtkCallbackCommand> click;
  vtkSmartPointer<vtkAxesActor> axes;
};

ModelView::ModelView(QWidget* parent) : QWidget(parent), impl_(std::make_unique<Impl>()) {
  auto* layout = new QVBoxLayout(this);
  layout->setContentsMargins(0, 0, 0, 0);
  impl_->widget = new QVTKOpenGLNativeWidget(this);
  impl_->widget->setRenderWindow(impl_->window);
  impl_->window->AddRenderer(impl_->renderer);
  impl_->renderer->SetBackground(0.12, 0.13, 0.16);
  impl_->renderer->SetBackground2(0.30, 0.32, 0.38);
  impl_->renderer->GradientBackgroundOn();
  layout->addWidget(impl_->widget);
  setMinimumSize(320, 240);
  impl_->picker->SetTolerance(0.002);
  impl_->click->SetClientData(this);
  impl_->click->SetCallback([](vtkObject* caller, unsigned long, void* client, void*) {
    auto* interactor = static_cast<vtkRenderWindowInteractor*>(caller);
    if (!interactor->GetShiftKey()) return;  // plain clicks turn the view
    static_cast<ModelView*>(client)->PickAt(interactor->GetEventPosition()[0], interactor->GetEventPosition()[1]);
  });
  if (auto* interactor = impl_->window->GetInteractor()) {
    interactor->AddObserver(vtkCommand::LeftButtonPressEvent, impl_->click, 1.0);
  }
}

void ModelView::PickAt(int x, int y) {
  impl_->click->SetAbortFlag(1);  // a pick, not the start of a camera turn
  if (!impl_->picker->Pick(x, y, 0, impl_->renderer)) {
    emit PickMissed(QString());
    return;
  }
  vtkActor* actor = impl_->picker->GetActor();
  for (const auto& [slot, a] : impl_->actors) {
    if (a.Get() != actor) continue;
    double p[3];
    impl_->picker->GetPickPosition(p);
    const Eigen::Vector3d room(p[0], p[1], p[2]);
    emit Picked(QString::fromStdString(slot), room, impl_->room_from_mesh[slot].Inverse() * room);
    return;
  }
  emit PickMissed(QString());
}

ModelView::~ModelView() = default;

namespace {
vtkSmartPointer<vtkPolyData> ToPolyData(const TriangleMesh& mesh, const Rigid3d& room_from_model) {
  vtkNew<vtkPoints> points;
  points->SetNumberOfPoints(static_cast<vtkIdType>(mesh.vertices.size()));
  for (size_t i = 0; i < mesh.vertices.size(); ++i) {
    const Eigen::Vector3d p = room_from_model * mesh.vertices[i].cast<double>();
    points->SetPoint(static_cast<vtkIdType>(i), p.x(), p.y(), p.z());
  }
  vtkNew<vtkCellArray> polys;
  for (const auto& f : mesh.faces) {
    const vtkIdType ids[3] = {f[0], f[1], f[2]};
    polys->InsertNextCell(3, ids);
  }
  auto poly = vtkSmartPointer<vtkPolyData>::New();
  poly->SetPoints(points);
  poly->SetPolys(polys);
  return poly;
}
}  // namespace

void ModelView::SetColoredMesh(const std::string& slot, const TriangleMesh& mesh, const Rigid3d& room_from_model,
                               const std::vector<std::array<std::uint8_t, 3>>& vertex_rgb, double opacity) {
  vtkSmartPointer<vtkPolyData> poly = ToPolyData(mesh, room_from_model);
  if (vertex_rgb.size() == mesh.vertices.size()) {
    vtkNew<vtkUnsignedCharArray> colours;
    colours->SetNumberOfComponents(3);
    colours->SetName("colours");
    colours->SetNumberOfTuples(static_cast<vtkIdType>(vertex_rgb.size()));
    for (size_t i = 0; i < vertex_rgb.size(); ++i) {
      for (int c = 0; c < 3; ++c) colours->SetComponent(static_cast<vtkIdType>(i), c, vertex_rgb[i][c]);
    }
    poly->GetPointData()->SetScalars(colours);
  }
  vtkNew<vtkPolyDataNormals> normals;
  normals->SetInputData(poly);
  normals->SplittingOff();
  vtkNew<vtkPolyDataMapper> mapper;
  mapper->SetInputConnection(normals->GetOutputPort());
  mapper->SetColorModeToDirectScalars();
  mapper->ScalarVisibilityOn();
  impl_->room_from_mesh[slot] = room_from_model;
  auto& actor = impl_->actors[slot];
  if (actor) impl_->renderer->RemoveActor(actor);
  actor = vtkSmartPointer<vtkActor>::New();
  actor->SetMapper(mapper);
  actor->GetProperty()->SetOpacity(opacity);
  impl_->renderer->AddActor(actor);
  impl_->window->Render();
}

void ModelView::SetPoints(const std::string& slot, const std::vector<Eigen::Vector3d>& points, double r, double g,
                          double b, double radius_m) {
  if (points.empty()) {
    RemoveMesh(slot);
    return;
  }
  TriangleMesh marks;
  const Eigen::Vector3d axes[6] = {{1, 0, 0}, {-1, 0, 0}, {0, 1, 0}, {0, -1, 0}, {0, 0, 1}, {0, 0, -1}};
  const int faces[8][3] = {{0, 2, 4}, {2, 1, 4}, {1, 3, 4}, {3, 0, 4}, {2, 0, 5}, {1, 2, 5}, {3, 1, 5}, {0, 3, 5}};
  for (const Eigen::Vector3d& p : points) {
    const int base = static_cast<int>(marks.vertices.size());
    for (const auto& a : axes) marks.vertices.push_back((p + radius_m * a).cast<float>());
    for (const auto& f : faces) marks.faces.emplace_back(base + f[0], base + f[1], base + f[2]);
  }
  SetMesh(slot, marks, Rigid3d::Identity(), r, g, b);
}

void ModelView::RemoveMesh(const std::string& slot) {
  auto it = impl_->actors.find(slot);
  if (it == impl_->actors.end()) return;
  impl_->renderer->RemoveActor(it->second);
  impl_->actors.erase(it);
  impl_->room_from_mesh.erase(slot);
  impl_->window->Render();
}

void ModelView::SetMesh(const std::string& slot, const TriangleMesh& mesh, const Rigid3d& room_from_model,
                        double r, double g, double b, double opacity) {
  vtkSmartPointer<vtkPolyData> poly = ToPolyData(mesh, room_from_model);
  vtkNew<vtkPolyDataNormals> normals;
  normals->SetInputData(poly);
  normals->SplittingOff();
  vtkNew<vtkPolyDataMapper> mapper;
  mapper->SetInputConnection(normals->GetOutputPort());
  impl_->room_from_mesh[slot] = room_from_model;
  auto& actor = impl_->actors[slot];
  if (actor) impl_->renderer->RemoveActor(actor);
  actor = vtkSmartPointer<vtkActor>::New();
  actor->SetMapper(mapper);
  actor->GetProperty()->SetColor(r, g, b);
  actor->GetProperty()->SetOpacity(opacity);
  impl_->renderer->AddActor(actor);
  impl_->window->Render();
}

void ModelView::ClearMeshes() {
  for (auto& [slot, actor] : impl_->actors) impl_->renderer->RemoveActor(actor);
  impl_->actors.clear();
  impl_->room_from_mesh.clear();
  impl_->window->Render();
}

void ModelView::ShowRoomAxes(double length_m) {
  if (!impl_->axes) {
    impl_->axes = vtkSmartPointer<vtkAxesActor>::New();
    impl_->renderer->AddActor(impl_->axes);
  }
  impl_->axes->SetTotalLength(length_m, length_m, length_m);
  impl_->axes->SetAxisLabels(0);
}

void ModelView::ResetCamera() {
  impl_->renderer->ResetCamera();
  impl_->window->Render();
}

QImage ModelView::Grab() {
  impl_->window->Render();
  return impl_->widget->grabFramebuffer();
}

}  // namespace arpos::ui
