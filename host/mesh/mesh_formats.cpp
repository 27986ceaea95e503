#include "host/mesh/mesh_formats.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <map>
#include <unordered_map>

#include "host/mesh/load_error.hpp"
#include "host/mesh/text_cursor.hpp"

namespace arnav::host {
namespace {

constexpr long long kMaxCount = 1LL << 26;  // refuse absurd header counts before allocating

void check_count(TextCursor& in, long long n, const char* what) {
  if (n < 0 || n > kMaxCount) in.fail(std::string(what) + " " + std::to_string(n) + " is out of range", "fix the count in the header");
}

// Splits a line into whitespace-separated tokens.
std::vector<std::string_view> split(std::string_view line) {
  std::vector<std::string_view> out;
  std::size_t i = 0;
  while (i < line.size()) {
    while (i < line.size() && (line[i] == ' ' || line[i] == '\t' || line[i] == '\r')) ++i;
    const std::size_t s = i;
    while (i < line.size() && line[i] != ' ' && line[i] != '\t' && line[i] != '\r') ++i;
    if (i > s) out.push_back(line.substr(s, i - s));
  }
  return out;
}

}  // namespace

TriMesh parse_obj(std::string_view content, const std::string& source, ElementLines* lines) {
  TriMesh out;
  std::vector<Eigen::Vector3d> v;
  int line_no = 0;
  std::size_t pos = 0;
  while (pos < content.size()) {
    std::size_t end = content.find('\n', pos);
    if (end == std::string_view::npos) end = content.size();
    const std::string_view line = content.substr(pos, end - pos);
    pos = end + 1;
    ++line_no;
    const auto t = split(line);
    if (t.empty() || t[0][0] == '#') continue;
    if (t[0] == "v") {
      TextCursor in(line.substr(line.find('v') + 1), source);
      Eigen::Vector3d p;
      for (int k = 0; k < 3; ++k) {
        try {
          p[k] = in.real("vertex coordinate");
        } catch (const LoadError&) {
          throw_load_error(source, line_no, "vertex line needs three finite numbers: '" + std::string(line.substr(0, 80)) + "'",
                           "fix the coordinates (NaN/Inf are not allowed)");
        }
      }
      v.push_back(p);
    } else if (t[0] == "f") {
      std::vector<int> ids;
      for (std::size_t k = 1; k < t.size(); ++k) {
        const std::string_view ref = t[k].substr(0, t[k].find('/'));
        long long idx = 0;
        const auto [e, ec] = std::from_chars(ref.data(), ref.data() + ref.size(), idx);
        if (ec != std::errc() || e != ref.data() + ref.size() || idx == 0 || idx > kMaxCount || idx < -kMaxCount)
          throw_load_error(source, line_no, "bad face vertex reference '" + std::string(t[k].substr(0, 40)) + "'",
                           "face entries are 1-based vertex numbers (v, v/vt, v/vt/vn or v//vn)");
        // Negative indices count back from the last vertex read so far (OBJ rule).
        ids.push_back(static_cast<int>(idx > 0 ? idx - 1 : static_cast<long long>(v.size()) + idx));
      }
      if (ids.size() < 3) throw_load_error(source, line_no, "face with fewer than 3 vertices", "remove the line");
      for (std::size_t k = 1; k + 1 < ids.size(); ++k) {
        out.tris.push_back({ids[0], ids[k], ids[k + 1]});
        if (lines) lines->push_back(line_no);
      }
    }
    // vn, vt, g, o, s, usemtl, mtllib, l: not geometry of a closed surface; ignored.
  }
  out.positions_World_mm.resize(3, static_cast<int>(v.size()));
  for (std::size_t i = 0; i < v.size(); ++i) out.positions_World_mm.col(static_cast<int>(i)) = v[i];
  return out;
}

TriMesh parse_off(std::string_view content, const std::string& source, ElementLines* lines) {
  TextCursor in(content, source);
  in.skip_comment_lines('#');
  if (in.token("OFF header") != "OFF") in.fail("not an OFF file (first word must be OFF)", "give an OFF surface");
  in.skip_comment_lines('#');
  const long long nv = in.integer("vertex count");
  const long long nf = in.integer("face count");
  in.integer("edge count");
  check_count(in, nv, "vertex count");
  check_count(in, nf, "face count");
  TriMesh out;
  out.positions_World_mm.resize(3, nv);
  for (long long i = 0; i < nv; ++i) {
    in.skip_comment_lines('#');
    for (int k = 0; k < 3; ++k) out.positions_World_mm(k, i) = in.real("vertex coordinate");
  }
  for (long long f = 0; f < nf; ++f) {
    in.skip_comment_lines('#');
    const long long n = in.integer("face size");
    const int line = in.line();
    if (n < 3 || n > 1000) in.fail("face " + std::to_string(f) + " has " + std::to_string(n) + " vertices", "faces need 3 or more");
    std::vector<int> ids(static_cast<std::size_t>(n));
    for (auto& id : ids) id = in.index("face vertex index");
    // Optional colour values may follow on the same line: skip the rest of it.
    in.rest_of_line();
    for (std::size_t k = 1; k + 1 < ids.size(); ++k) {
      out.tris.push_back({ids[0], ids[k], ids[k + 1]});
      if (lines) lines->push_back(line);
    }
  }
  return out;
}

TetMesh parse_tetgen(std::string_view node_content, const std::string& node_source, std::string_view ele_content,
                     const std::string& ele_source, ElementLines* lines) {
  TextCursor nodes(node_content, node_source);
  nodes.skip_comment_lines('#');
  const long long nv = nodes.integer("node count");
  const long long dim = nodes.integer("dimension");
  const long long nattr = nodes.integer("attribute count");
  const long long nmark = nodes.integer("boundary marker flag");
  check_count(nodes, nv, "node count");
  if (dim != 3) nodes.fail("dimension is " + std::to_string(dim), "a volume mesh needs dimension 3");
  if (nattr < 0 || nattr > 100 || nmark < 0 || nmark > 1) nodes.fail("bad attribute count or marker flag", "fix the header");
  TetMesh out;
  out.rest_positions_World_mm.resize(3, nv);
  long long first = 0;
  for (long long i = 0; i < nv; ++i) {
    nodes.skip_comment_lines('#');
    const long long id = nodes.integer("node number");
    if (i == 0) first = id;
    if (first != 0 && first != 1) nodes.fail("node numbers must start at 0 or 1, found " + std::to_string(first), "renumber the nodes");
    if (id != first + i)
      nodes.fail("node number " + std::to_string(id) + " where " + std::to_string(first + i) + " was expected",
                 "TetGen node files list nodes consecutively");
    for (int k = 0; k < 3; ++k) out.rest_positions_World_mm(k, i) = nodes.real("node coordinate");
    for (long long a = 0; a < nattr + nmark; ++a) nodes.real("node attribute");
  }
  TextCursor ele(ele_content, ele_source);
  ele.skip_comment_lines('#');
  const long long nt = ele.integer("tetrahedron count");
  const long long per = ele.integer("nodes per tetrahedron");
  const long long eattr = ele.integer("region attribute count");
  check_count(ele, nt, "tetrahedron count");
  if (per != 4) ele.fail(std::to_string(per) + " nodes per tetrahedron", "only linear (4-node) tetrahedra are supported: run tetgen without -o2");
  if (eattr < 0 || eattr > 100) ele.fail("bad attribute count", "fix the header");
  std::map<double, int> region_of_attr;  // TetGen region attributes are reals
  for (long long t = 0; t < nt; ++t) {
    ele.skip_comment_lines('#');
    ele.integer("tetrahedron number");
    const int line = ele.line();
    std::array<int, 4> tet{};
    for (int& v : tet) {
      const long long id = ele.integer("tetrahedron node");
      if (id < first || id >= first + nv)
        ele.fail("tetrahedron " + std::to_string(t) + " refers to node " + std::to_string(id) + " but the node file " + node_source +
                     " numbers nodes " + std::to_string(first) + ".." + std::to_string(first + nv - 1),
                 "fix the index, or pair the .ele with its own .node file");
      v = static_cast<int>(id - first);
    }
    if (eattr > 0) {
      const double attr = ele.real("region attribute");
      for (long long a = 1; a < eattr; ++a) ele.real("attribute");
      if (!std::isfinite(attr)) {
        ele.fail("tetrahedron " + std::to_string(t) + " has a region attribute that is not a finite number",
                 "fix the attribute column (tetgen -A writes one finite value per region)");
      }
      auto [it, inserted] = region_of_attr.emplace(attr, static_cast<int>(region_of_attr.size()));
      out.tet_region.push_back(it->second);
    }
    out.tets.push_back(tet);
    if (lines) lines->push_back(line);
  }
  if (!region_of_attr.empty()) {
    out.region_names.resize(region_of_attr.size());
    for (const auto& [attr, idx] : region_of_attr) {
      char name[48];
      std::snprintf(name, sizeof name, "region_%.15g", attr);  // 1 -> "region_1", 0.5 -> "region_0.5"
      out.region_names[idx] = name;
    }
  }
  return out;
}

TetMesh parse_gmsh(std::string_view content, const std::string& source, ElementLines* lines) {
  // Line-based: every Gmsh ASCII record is one line.
  std::vector<std::pair<int, std::string_view>> rows;  // (line number, text) of non-empty lines
  {
    int line_no = 0;
    std::size_t pos = 0;
    while (pos < content.size()) {
      std::size_t end = content.find('\n', pos);
      if (end == std::string_view::npos) end = content.size();
      std::string_view line = content.substr(pos, end - pos);
      pos = end + 1;
      ++line_no;
      while (!line.empty() && (line.back() == '\r' || line.back() == ' ' || line.back() == '\t')) line.remove_suffix(1);
      if (!line.empty()) rows.emplace_back(line_no, line);
    }
  }
  auto fail = [&](int line, const std::string& what, const std::string& fix) { throw_load_error(source, line, what, fix); };
  auto to_ll = [&](std::string_view t, int line, const char* what) {
    long long v = 0;
    const auto [e, ec] = std::from_chars(t.data(), t.data() + t.size(), v);
    if (ec != std::errc() || e != t.data() + t.size())
      fail(line, std::string("expected an integer for ") + what + ", found '" + std::string(t.substr(0, 40)) + "'",
           "check the line for a missing or malformed value");
    return v;
  };
  auto to_d = [&](std::string_view t, int line, const char* what) {
    TextCursor c(t, source);
    try {
      return c.real(what);
    } catch (const LoadError&) {
      throw_load_error(source, line, std::string("expected a finite number for ") + what + ", found '" + std::string(t.substr(0, 40)) + "'",
                       "fix the coordinate (NaN/Inf are not allowed)");
    }
  };
  if (rows.empty()) fail(0, "empty file", "give a Gmsh .msh file");
  std::size_t r = 0;
  int version = 1;
  if (rows[0].second == "$MeshFormat") {
    if (rows.size() < 3) fail(rows[0].first, "truncated $MeshFormat", "re-export the mesh");
    const auto f = split(rows[1].second);
    if (f.size() < 3) fail(rows[1].first, "$MeshFormat needs 'version file-type data-size'", "re-export the mesh");
    if (f[0].substr(0, 1) != "2")
      fail(rows[1].first, "Gmsh format version " + std::string(f[0]) + " is not supported",
           "save as version 2 ASCII (gmsh -save -format msh2 mesh.msh)");
    if (f[1] != "0") fail(rows[1].first, "binary Gmsh files are not supported", "save as ASCII (gmsh -save -format msh2)");
    version = 2;
    r = 3;  // $MeshFormat, line, $EndMeshFormat
  }
  const std::string nodes_tag = version == 1 ? "$NOD" : "$Nodes";
  const std::string elems_tag = version == 1 ? "$ELM" : "$Elements";
  std::unordered_map<long long, int> node_index;
  std::vector<Eigen::Vector3d> p;
  std::map<long long, std::string> physical_names;
  std::vector<std::pair<std::array<long long, 4>, std::pair<long long, int>>> raw_tets;  // nodes, (physical, line)
  bool have_nodes = false, have_elements = false;
  for (; r < rows.size(); ++r) {
    const auto [line, text] = rows[r];
    if (text == "$PhysicalNames") {
      const long long n = to_ll(r + 1 < rows.size() ? rows[r + 1].second : "", line, "physical name count");
      if (n < 0 || r + 2 + static_cast<std::size_t>(n) > rows.size()) fail(line, "truncated $PhysicalNames", "re-export the mesh");
      for (long long i = 0; i < n; ++i) {
        const auto [l2, t2] = rows[r + 2 + i];
        const auto f = split(t2);
        if (f.size() < 3) fail(l2, "physical name line needs 'dimension tag \"name\"'", "re-export the mesh");
        std::string name(t2.substr(t2.find(f[2])));
        name.erase(std::remove(name.begin(), name.end(), '"'), name.end());
        physical_names[to_ll(f[1], l2, "physical tag")] = name;
      }
      r += 2 + n;  // now at $EndPhysicalNames
    } else if (text == nodes_tag) {
      if (r + 1 >= rows.size()) fail(line, "truncated " + nodes_tag, "re-export the mesh");
      const long long n = to_ll(rows[r + 1].second, rows[r + 1].first, "node count");
      if (n < 0 || n > kMaxCount || r + 2 + static_cast<std::size_t>(n) > rows.size())
        fail(rows[r + 1].first, "node count " + std::to_string(n) + " does not match the file", "fix the count or re-export");
      for (long long i = 0; i < n; ++i) {
        const auto [l2, t2] = rows[r + 2 + i];
        const auto f = split(t2);
        if (f.size() != 4) fail(l2, "node line needs 'number x y z'", "fix the line (the node count may be wrong)");
        const long long id = to_ll(f[0], l2, "node number");
        if (!node_index.emplace(id, static_cast<int>(p.size())).second)
          fail(l2, "node number " + std::to_string(id) + " appears twice", "renumber the nodes");
        p.emplace_back(to_d(f[1], l2, "x"), to_d(f[2], l2, "y"), to_d(f[3], l2, "z"));
      }
      r += 2 + n;
      if (r >= rows.size() || rows[r].second != (version == 1 ? "$ENDNOD" : "$EndNodes"))
        fail(r < rows.size() ? rows[r].first : rows.back().first, "expected the end of the node section after " + std::to_string(n) + " nodes",
             "the node count does not match the data; fix it");
      have_nodes = true;
    } else if (text == elems_tag) {
      if (r + 1 >= rows.size()) fail(line, "truncated " + elems_tag, "re-export the mesh");
      const long long n = to_ll(rows[r + 1].second, rows[r + 1].first, "element count");
      if (n < 0 || n > kMaxCount || r + 2 + static_cast<std::size_t>(n) > rows.size())
        fail(rows[r + 1].first, "element count " + std::to_string(n) + " does not match the file", "fix the count or re-export");
      for (long long i = 0; i < n; ++i) {
        const auto [l2, t2] = rows[r + 2 + i];
        const auto f = split(t2);
        // v1: number type physical elementary n-nodes nodes...; v2: number type n-tags tags... nodes...
        if (f.size() < 3) fail(l2, "element line too short", "re-export the mesh");
        const long long type = to_ll(f[1], l2, "element type");
        std::size_t first_node;
        long long physical = 0;
        if (version == 1) {
          if (f.size() < 5) fail(l2, "element line too short", "v1 lines are 'number type physical elementary n nodes...'");
          physical = to_ll(f[2], l2, "physical tag");
          first_node = 5;
          if (static_cast<long long>(f.size()) - 5 != to_ll(f[4], l2, "node count"))
            fail(l2, "element node count does not match the nodes on the line", "fix the line");
        } else {
          const long long ntags = to_ll(f[2], l2, "tag count");
          if (ntags < 0 || 3 + static_cast<std::size_t>(ntags) > f.size()) fail(l2, "tag count exceeds the line", "fix the line");
          if (ntags > 0) physical = to_ll(f[3], l2, "physical tag");
          first_node = 3 + static_cast<std::size_t>(ntags);
        }
        const std::size_t nn = f.size() - first_node;
        if (type == 1 || type == 2 || type == 3 || type == 15) continue;  // lines, triangles, quads, points
        if (type != 4)
          fail(l2, "element type " + std::to_string(type) + " is not a linear tetrahedron (type 4)",
               "mesh the volume with linear tetrahedra (Gmsh: Mesh.ElementOrder = 1, no hexahedra/prisms)");
        if (nn != 4) fail(l2, "tetrahedron with " + std::to_string(nn) + " nodes", "a linear tetrahedron has 4 nodes");
        std::array<long long, 4> ids{};
        for (int k = 0; k < 4; ++k) ids[k] = to_ll(f[first_node + k], l2, "node number");
        raw_tets.push_back({ids, {physical, l2}});
      }
      r += 2 + n;
      if (r >= rows.size() || rows[r].second != (version == 1 ? "$ENDELM" : "$EndElements"))
        fail(r < rows.size() ? rows[r].first : rows.back().first, "expected the end of the element section after " + std::to_string(n) + " elements",
             "the element count does not match the data; fix it");
      have_elements = true;
    } else if (text[0] == '$' && text.substr(0, 4) != "$End" && text.substr(0, 4) != "$END") {
      // Other sections ($Periodic, $NodeData, ...): skip to their end marker.
      const std::string end_tag = "$End" + std::string(text.substr(1));
      while (r + 1 < rows.size() && rows[r + 1].second != end_tag) ++r;
      ++r;
    } else {
      fail(line, "unexpected line '" + std::string(text.substr(0, 40)) + "' between sections", "fix the file structure");
    }
  }
  if (!have_nodes || !have_elements)
    fail(0, std::string("missing ") + (have_nodes ? elems_tag : nodes_tag) + " section", "give a complete Gmsh mesh");
  TetMesh out;
  out.rest_positions_World_mm.resize(3, static_cast<int>(p.size()));
  for (std::size_t i = 0; i < p.size(); ++i) out.rest_positions_World_mm.col(static_cast<int>(i)) = p[i];
  std::map<long long, int> region_of_physical;
  for (const auto& [ids, info] : raw_tets) region_of_physical.emplace(info.first, 0);
  int next = 0;
  for (auto& [phys, idx] : region_of_physical) idx = next++;
  for (std::size_t t = 0; t < raw_tets.size(); ++t) {
    const auto& [ids, info] = raw_tets[t];
    std::array<int, 4> tet{};
    for (int k = 0; k < 4; ++k) {
      const auto it = node_index.find(ids[k]);
      if (it == node_index.end())
        fail(info.second, "tetrahedron " + std::to_string(t) + " refers to node " + std::to_string(ids[k]) + " which is not in the node section",
             "fix the node number or add the node");
      tet[k] = it->second;
    }
    out.tets.push_back(tet);
    out.tet_region.push_back(region_of_physical.size() > 1 ? region_of_physical[info.first] : 0);
    if (lines) lines->push_back(info.second);
  }
  if (region_of_physical.size() > 1) {
    for (const auto& [phys, idx] : region_of_physical) {
      const auto name = physical_names.find(phys);
      out.region_names.push_back(name != physical_names.end() ? name->second : "physical_" + std::to_string(phys));
    }
  } else {
    out.region_names = {"default"};
  }
  return out;
}

}  // namespace arnav::host
