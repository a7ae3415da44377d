// libtorch (libtorch-dev) at batch 1 on the network infer_c wrote: an
// at::addmm/elu chain, median of 10000 runs; prints JSON and output[0] so the
// comparison checks the same network ran. Usage: infer_torch SIZES WEIGHTS
#include <torch/torch.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <sstream>
#include <string>
#include <vector>

int main(int argc, char **argv)
{
    if (argc < 3)
        return 2;
    torch::set_num_threads(1);
    std::vector<int64_t> sz;
    std::stringstream ss(argv[1]);
    for (std::string t; std::getline(ss, t, ',');)
        sz.push_back(std::stoll(t));
    FILE *f = std::fopen(argv[2], "rb");
    if (!f)
        return 1;
    std::vector<torch::Tensor> w, b;
    for (size_t k = 0; k + 1 < sz.size(); k++) {
        auto wt = torch::empty({sz[k + 1], sz[k]});
        auto bt = torch::empty({sz[k + 1]});
        if (std::fread(wt.data_ptr<float>(), 4, wt.numel(), f) != (size_t)wt.numel() ||
            std::fread(bt.data_ptr<float>(), 4, bt.numel(), f) != (size_t)bt.numel())
            return 1;
        w.push_back(wt.t().contiguous());
        b.push_back(bt.unsqueeze(0));
    }
    auto x0 = torch::empty({1, sz[0]});
    if (std::fread(x0.data_ptr<float>(), 4, x0.numel(), f) != (size_t)x0.numel())
        return 1;
    std::fclose(f);
    torch::NoGradGuard ng;
    auto run = [&]() {
        auto x = x0;
        for (size_t k = 0; k < w.size(); k++) {
            x = at::addmm(b[k], x, w[k]);
            if (k + 1 < w.size())
                x = at::elu(x);
        }
        return x;
    };
    std::vector<double> t;
    torch::Tensor y;
    for (int r = 0; r < 10100; r++) {
        auto t0 = std::chrono::steady_clock::now();
        y = run();
        auto dt = std::chrono::duration<double, std::nano>(std::chrono::steady_clock::now() - t0);
        if (r >= 100)
            t.push_back(dt.count());
    }
    std::sort(t.begin(), t.end());
    std::printf("{\"libtorch_ns\": {\"p50\": %.0f, \"p99\": %.0f}, \"out0\": %.6f}\n",
                t[t.size() / 2], t[t.size() * 99 / 100], y[0][0].item<float>());
    return 0;
}
