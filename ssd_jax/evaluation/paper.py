"""The paper's published numbers, printed beside recomputed ones (docs/method.md §4)."""

# Tables I / II, the paper's own runs: (RTE m, RRE deg, success %, avg #iter).
REGISTRATION = {
    'oxford': {'iss+fpfh': (0.354, 1.43, 93.37, 3239), 'iss+feat3dnet': (0.314, 1.08, 97.66, 7126),
               'iss+ours': (0.311, 1.01, 98.10, 5648),
               'feat3dnet+feat3dnet': (0.304, 1.08, 97.66, 3294),
               'feat3dnet+ours': (0.310, 1.08, 97.05, 3650)},
    'kitti': {'iss+feat3dnet': (0.246, 0.627, 93.50, 8311), 'iss+ours': (0.215, 0.510, 93.50, 5960),
              'feat3dnet+feat3dnet': (0.264, 0.599, 95.58, 4394),
              'feat3dnet+ours': (0.258, 0.570, 95.44, 3732)},
}

# Fig. 4, read off at x = 1 m: "both 3DFeatNet Desc and our model achieve around 15 %".
PRECISION_AT_1M = {'feat3dnet': 15.0, 'ours': 15.0}

# Descriptor matching on 30,000 random-location cluster pairs, FPR (%) at 95 % recall.
# Ours is the paper's run; FPFH and 3DFeat-Net are quoted from 3DFeat-Net's paper.
DESCRIPTOR_MATCHING = {'ours': 66.33, 'fpfh': 54.13, 'feat3dnet': 36.84}

# Table III, ISS-filtered pairs: r_th (m) -> ((positives, negatives), {descriptor: FPR %}).
ISS_FILTERED = {
    0.1: ((34, 24), {'feat3dnet': 37.5, 'ours': 29.17}),
    0.2: ((103, 75), {'feat3dnet': 28.0, 'ours': 13.33}),
    0.3: ((407, 315), {'feat3dnet': 31.43, 'ours': 53.65}),
    0.4: ((850, 751), {'feat3dnet': 35.955, 'ours': 56.99}),
}
