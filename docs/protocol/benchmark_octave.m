% The paper's benchmark, eq. (5), in Octave, served to twostage:
%   octave-cli --no-gui --quiet --norc benchmark_octave.m
% x1(k+1) = x1(k)/2 + u(k) + v11(k)
% x2(k+1) = (1 - theta^2) sin(50 theta^2) x1(k) - theta x2(k) + theta/(1 + theta^2) u(k) + v12(k)
% y(k)    = x2(k) + v2(k),  u, v11, v12 ~ N(0, 1), v2 ~ N(0, 0.1)
1;
addpath(fileparts(mfilename("fullpath")));

function [u, y] = simulate(theta, seed, index, n)
  randn("state", twostage_seed_state(seed, index));
  u = randn(n, 1);
  v = randn(n, 3);
  a = (1 - theta^2) * sin(50 * theta^2);
  b = theta / (1 + theta^2);
  x1 = 0; x2 = 0; y = zeros(n, 1);
  for k = 1:n
    y(k) = x2 + sqrt(0.1) * v(k, 3);
    [x1, x2] = deal(0.5 * x1 + u(k) + v(k, 1), a * x1 - theta * x2 + b * u(k) + v(k, 2));
  end
end

twostage_serve(@simulate);
