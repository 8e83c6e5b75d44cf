#include "pmsc/RowBlockOps.h"

#include "pmsc/KeyPointSelector.h"
#include "pmsc/Model.h"

#include <numeric>
#include <stdexcept>

namespace pmsc {

Eigen::MatrixXd gramOf(RowBlocks& q, Communicator& comm) {
    const Index f = q.frames();
    Eigen::MatrixXd gram = Eigen::MatrixXd::Zero(f, f);
    for (Index b = 0; b < q.blockCount(); ++b)
        gram.selfadjointView<Eigen::Lower>().rankUpdate(q.block(b).transpose());
    comm.sum(gram.data(), static_cast<std::size_t>(gram.size()));
    gram.triangularView<Eigen::StrictlyUpper>() = gram.transpose();
    return gram;
}

Eigen::MatrixXd timesRight(RowBlocks& q, const Eigen::MatrixXd& w) {
    Eigen::MatrixXd out(q.ownedRows(), w.cols());
    for (Index b = 0; b < q.blockCount(); ++b) {
        out.middleRows(q.blockFirstRow(b), q.blockRows(b)).noalias() = q.block(b) * w;
    }
    return out;
}

Eigen::MatrixXd transposeTimes(RowBlocks& q, Communicator& comm, const Eigen::MatrixXd& localB) {
    Eigen::MatrixXd out = Eigen::MatrixXd::Zero(localB.cols(), q.frames());
    for (Index b = 0; b < q.blockCount(); ++b) {
        out.noalias() += localB.middleRows(q.blockFirstRow(b), q.blockRows(b)).transpose() * q.block(b);
    }
    comm.sum(out.data(), static_cast<std::size_t>(out.size()));
    return out;
}

double maxPointResidualOf(RowBlocks& q, Communicator& comm, const Eigen::MatrixXd& localB,
                          const Eigen::MatrixXd& coords) {
    double worst = 0;
    for (Index b = 0; b < q.blockCount(); ++b) {
        const double w = maxPointResidual(q.block(b), localB.middleRows(q.blockFirstRow(b), q.blockRows(b)),
                                          coords, q.channels());
        if (!(w <= worst)) worst = w;  // NaN wins
    }
    maxOverRanks(comm, &worst, 1);
    return worst;
}

Eigen::MatrixXd keyRowsOfQ(RowBlocks& q, Communicator& comm, const std::vector<Index>& keys) {
    const Index c = q.channels();
    Eigen::MatrixXd out = Eigen::MatrixXd::Zero(static_cast<Index>(keys.size()) * c, q.frames());
    for (std::size_t i = 0; i < keys.size(); ++i) {
        if (q.owns(keys[i])) q.pointRows(keys[i], out.middleRows(static_cast<Index>(i) * c, c));
    }
    comm.sum(out.data(), static_cast<std::size_t>(out.size()));
    return out;
}

Eigen::MatrixXd keyRowsOf(const RowBlocks& layout, Communicator& comm, const Eigen::MatrixXd& local,
                          const std::vector<Index>& keys) {
    const Index c = layout.channels();
    Eigen::MatrixXd out = Eigen::MatrixXd::Zero(static_cast<Index>(keys.size()) * c, local.cols());
    for (std::size_t i = 0; i < keys.size(); ++i) {
        if (!layout.owns(keys[i])) continue;
        out.middleRows(static_cast<Index>(i) * c, c) =
            local.middleRows((keys[i] - layout.firstPoint()) * c, c);
    }
    comm.sum(out.data(), static_cast<std::size_t>(out.size()));
    return out;
}

Eigen::MatrixXd gatherRowsTo(Communicator& comm, const Eigen::MatrixXd& local, Index totalRows, int root) {
    Eigen::MatrixXd full;
    if (comm.size() == 1) return local;
    if (comm.rank() == root) full.resize(totalRows, local.cols());
    std::vector<double> column;
    for (Index j = 0; j < local.cols(); ++j) {
        comm.gather(local.col(j).data(), static_cast<std::size_t>(local.rows()), column, root);
        if (comm.rank() == root) {
            if (static_cast<Index>(column.size()) != totalRows) {
                throw std::logic_error("gatherRowsTo: ranks hold " + std::to_string(column.size()) +
                                       " rows, expected " + std::to_string(totalRows));
            }
            full.col(j) = Eigen::Map<const Eigen::VectorXd>(column.data(), totalRows);
        }
    }
    return full;
}

Eigen::MatrixXd projectorFromKeyRows(const Eigen::MatrixXd& keyRows, Index channels) {
    std::vector<Index> all(static_cast<std::size_t>(keyRows.rows() / channels));
    std::iota(all.begin(), all.end(), Index{0});
    return makeProjector(keyRows, channels, all);
}

}  // namespace pmsc
